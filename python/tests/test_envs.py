"""The Gymnasium API: registration, check_env, seeding, episode ends,
same-step auto-reset, zero copy, rendering and errors."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError
from gymnasium.utils.env_checker import check_env

import worldgraph

# A corridor: forward from the start reaches the exit in one step.
EXIT_AHEAD = "####\n#>E#\n####\n"


@pytest.mark.parametrize("env_id", worldgraph.ENV_IDS)
def test_check_env_passes_on_every_registered_id(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught if "worldgraph" in str(w.filename) or "gymnasium" in str(w.filename)] == []
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()


@pytest.mark.parametrize("env_id", worldgraph.ENV_IDS)
def test_make_vec_gives_the_native_vector_env_with_declared_spaces(env_id: str) -> None:
    envs = gym.make_vec(env_id, num_envs=4)
    assert isinstance(envs.unwrapped, worldgraph.WorldGraphVectorEnv)
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    obs, info = envs.reset(seed=3)
    assert obs in envs.observation_space and info == {}
    envs.action_space.seed(0)
    for _ in range(20):
        obs, rew, term, trunc, info = envs.step(envs.action_space.sample())
        assert obs in envs.observation_space
        assert rew.shape == (4,) and term.dtype == np.bool_ and trunc.dtype == np.bool_
    envs.close()


def rollout(num_envs: int, threads: int, seed: int, steps: int, task: str = "multigoal-stochastic"):
    envs = worldgraph.WorldGraphVectorEnv(num_envs, task=task, maze="medium", threads=threads, max_steps=50)
    rng = np.random.default_rng(7)
    obs, _ = envs.reset(seed=seed)
    out = [obs["grid"].copy(), obs["agent"].copy()]
    n_actions = envs.single_action_space.n
    for _ in range(steps):
        obs, r, te, tr, info = envs.step(rng.integers(0, n_actions, num_envs, dtype=np.int64))
        out += [obs["grid"].copy(), obs["agent"].copy(), r.copy(), te.copy(), tr.copy()]
    envs.close()
    return out


def test_the_same_seed_gives_the_same_trajectories_whatever_the_thread_count() -> None:
    one = rollout(200, 1, 11, 120)
    for threads in (2, 3):
        other = rollout(200, threads, 11, 120)
        assert all(np.array_equal(a, b) for a, b in zip(one, other, strict=True)), threads
    different = rollout(200, 2, 12, 120)
    assert not all(np.array_equal(a, b) for a, b in zip(one, different, strict=True))


def test_a_reset_with_the_same_seed_repeats_and_an_unseeded_reset_continues() -> None:
    envs = worldgraph.WorldGraphVectorEnv(16, task="multigoal", maze="small")
    first, _ = envs.reset(seed=5)
    first = {k: v.copy() for k, v in first.items()}
    again, _ = envs.reset(seed=5)
    assert np.array_equal(first["grid"], again["grid"])
    nxt, _ = envs.reset()
    assert not np.array_equal(first["grid"], nxt["grid"])  # new ball positions
    env = gym.make("worldgraph/MultiGoal-Small-v0")
    a, _ = env.reset(seed=5)
    # The single env on seed s is environment 0 of the batch on seed s.
    assert np.array_equal(a["grid"], first["grid"][0]) and np.array_equal(a["agent"], first["agent"][0])


def test_terminated_and_truncated_are_separate() -> None:
    env = gym.make("worldgraph/Custom-v0", layout=EXIT_AHEAD, task="multigoal", max_steps=3)
    env.reset(seed=0)
    _, r, term, trunc, info = env.step(worldgraph.ACTIONS["forward"])
    assert (term, trunc) == (True, False) and r == pytest.approx(0.99)
    assert info == {"balls": 0}  # episode statistics are RecordEpisodeStatistics' to write
    env.reset()
    for t in range(3):
        _, r, term, trunc, _ = env.step(worldgraph.ACTIONS["left"])
        assert term is False and trunc is (t == 2)
        assert r == pytest.approx(-0.01)


def test_same_step_autoreset_returns_the_next_episode_and_the_final_observation() -> None:
    envs = worldgraph.WorldGraphVectorEnv(3, task="multigoal", layout=EXIT_AHEAD, max_steps=2, balls=0)
    obs, _ = envs.reset(seed=0)
    start = obs["agent"].copy()
    assert start[0].tolist() == [1, 1, 0, 255]
    # env 0 walks onto the exit, env 1 turns (truncated at its 2nd step), env 2 turns.
    obs, r, term, trunc, info = envs.step(np.array([2, 0, 1]))
    assert term.tolist() == [True, False, False] and trunc.tolist() == [False, False, False]
    # Same step: the observation is the next episode's first ...
    assert obs["agent"][0].tolist() == [1, 1, 0, 255]
    # ... and the finished episode's last observation is in the info.
    assert info["_final_obs"].tolist() == [True, False, False]
    assert info["final_obs"][0]["agent"].tolist() == [2, 1, 0, 255]
    assert info["final_obs"][0]["grid"][1, 2] == worldgraph.OBJECTS["exit"]
    assert info["final_obs"][1] is None
    assert info["final_info"]["episode"]["r"][0] == pytest.approx(0.99)
    assert info["final_info"]["episode"]["l"][0] == 1 and info["final_info"]["_episode"].tolist() == [True, False, False]
    assert envs.final_obs["agent"][0].tolist() == [2, 1, 0, 255]
    obs, r, term, trunc, info = envs.step(np.array([1, 0, 1]))
    assert term.tolist() == [False, False, False] and trunc.tolist() == [False, True, True]
    assert info["final_obs"][1]["agent"].tolist() == [1, 1, 2, 255]  # two left turns: facing left
    assert info["final_obs"][2]["agent"].tolist() == [1, 1, 2, 255]
    assert obs["agent"][1].tolist() == [1, 1, 0, 255]  # reset to the start
    assert obs["agent"][0].tolist() == [1, 1, 1, 255]  # env 0 goes on in its new episode
    obs, r, term, trunc, info = envs.step(np.array([1, 1, 1]))
    # env 0's second episode reaches its limit; the others are one step in.
    assert trunc.tolist() == [True, False, False] and info["_final_obs"].tolist() == [True, False, False]
    obs, r, term, trunc, info = envs.step(np.array([2, 1, 1]))
    assert term.tolist() == [True, False, False] and trunc.tolist() == [False, True, True]
    obs, r, term, trunc, info = envs.step(np.array([1, 0, 0]))
    assert info == {} and not term.any() and not trunc.any()


def test_observations_are_written_in_place_with_no_copy() -> None:
    envs = gym.make_vec("worldgraph/MultiGoalStochastic-Medium-v0", num_envs=64)
    obs, _ = envs.reset(seed=1)
    sim = envs.unwrapped.simulator
    grid_addr = obs["grid"].__array_interface__["data"][0]
    agent_addr = obs["agent"].__array_interface__["data"][0]
    assert grid_addr == sim.grid.__array_interface__["data"][0]
    before = obs["grid"].copy()
    for _ in range(10):
        obs2, rew, *_ = envs.step(np.full(64, 2))
        assert obs2["grid"].__array_interface__["data"][0] == grid_addr
        assert obs2["agent"].__array_interface__["data"][0] == agent_addr
        assert obs2["grid"] is obs["grid"]
        assert rew is sim.reward
    # The lava moved: the array handed out at reset changed under our feet.
    assert not np.array_equal(before, obs["grid"])
    copying = worldgraph.WorldGraphVectorEnv(4, copy=True)
    a, _ = copying.reset(seed=0)
    b, *_ = copying.step(np.zeros(4, dtype=np.uint8))
    assert not np.shares_memory(a["grid"], b["grid"])


def test_render_rgb_array() -> None:
    envs = worldgraph.WorldGraphVectorEnv(2, task="doorkey", maze="small", render_mode="rgb_array", cell_px=8)
    envs.reset(seed=0)
    frames = envs.render()
    assert len(frames) == 2 and frames[0].shape == (13 * 8, 13 * 8, 3)
    assert worldgraph.WorldGraphVectorEnv(2).render() is None


def test_a_malformed_layout_raises_a_layout_error_naming_line_and_column() -> None:
    bad = "#####\n#>xE#\n#####\n"
    with pytest.raises(worldgraph.LayoutError, match=r"line 2, column 3"):
        gym.make("worldgraph/Custom-v0", layout=bad)
    with pytest.raises(ValueError, match="ragged row"):
        worldgraph.WorldGraphVectorEnv(2, layout="#####\n#>.E#\n####\n")
    with pytest.raises(worldgraph.LayoutError, match="no exit"):
        worldgraph.check_layout("#####\n#>..#\n#####\n")
    with pytest.raises(ValueError, match="unknown maze"):
        worldgraph.WorldGraphEnv(maze="huge")
    with pytest.raises(ValueError, match="unknown task"):
        worldgraph.WorldGraphEnv(task="chess")


@pytest.mark.parametrize(
    ("actions", "error", "message"),
    [
        (np.zeros(5, dtype=np.int64), ValueError, r"shape \(4,\)"),
        (np.zeros((4, 1), dtype=np.int64), ValueError, r"shape \(4,\)"),
        (np.zeros(4, dtype=np.float32), TypeError, "integer array"),
        (np.zeros(4, dtype=bool), TypeError, "integer array"),
        (np.array([0, 1, 3, 0]), ValueError, r"action 3 of environment 2 is out of range"),
        (np.array([0, -1, 0, 0], dtype=np.int8), ValueError, r"action -1 of environment 1"),
        (np.array([0, 0, 0, 300], dtype=np.uint16), ValueError, r"action 300 of environment 3"),
        ([0, 1, 2], ValueError, r"shape \(4,\)"),
        ([0, 1, 2.0, 0], TypeError, "must be an int"),
        ("0123", TypeError, "integer array or a sequence"),
        (None, TypeError, "integer array or a sequence"),
    ],
)
def test_bad_action_arrays_raise_clear_errors(actions, error, message) -> None:
    envs = worldgraph.WorldGraphVectorEnv(4, task="multigoal")
    envs.reset(seed=0)
    before = envs.simulator.agent.copy()
    with pytest.raises(error, match=message):
        envs.step(actions)
    assert np.array_equal(before, envs.simulator.agent)  # nothing stepped
    envs.step(np.array([0, 1, 2, 0], dtype=np.int32))  # and it still works


def test_a_single_env_refuses_bad_actions() -> None:
    env = worldgraph.WorldGraphEnv(task="doorkey")
    env.reset(seed=0)
    env.step(5)
    env.step(np.int64(3))
    with pytest.raises(ValueError, match="out of range"):
        env.step(6)
    with pytest.raises(TypeError, match="must be an int"):
        env.step(1.0)
    with pytest.raises(TypeError, match="must be an int"):
        env.step(True)


def test_a_closed_env_raises_instead_of_crashing() -> None:
    envs = worldgraph.WorldGraphVectorEnv(4)
    envs.reset(seed=0)
    envs.close()
    envs.close()  # twice is fine
    assert envs.closed
    with pytest.raises(ClosedEnvironmentError):
        envs.step(np.zeros(4, dtype=np.int64))
    with pytest.raises(ClosedEnvironmentError):
        envs.reset()
    env = gym.make("worldgraph/DoorKey-Small-v0")
    env.reset(seed=0)
    env.close()
    with pytest.raises(ClosedEnvironmentError):
        env.step(0)
    sim = worldgraph.Simulator("multigoal", maze="small", num_envs=2)
    sim.close()
    with pytest.raises(worldgraph.ClosedError):
        sim.step([0, 0])
    with pytest.raises(worldgraph.ClosedError):
        sim.render()


def test_reset_options_and_seeds_are_checked() -> None:
    envs = worldgraph.WorldGraphVectorEnv(2)
    with pytest.raises(ValueError, match="unknown reset options"):
        envs.reset(options={"reset_mask": np.ones(2, dtype=bool)})
    with pytest.raises(TypeError, match="one int"):
        envs.reset(seed=[1, 2])
    envs.reset(options={})


def test_a_step_releases_the_gil() -> None:
    """Another Python thread runs while the simulator steps. A step of
    300,000 environments takes tens of milliseconds, most of it in the
    batch's step (the rest copies the small per-environment records out);
    with the GIL held there, the other thread could run only where the
    interpreter switches threads, at the call's start (within one switch
    interval, set to 1 ms here), never from 2 ms to a third of the call.
    (Checked: with the release taken out of Simulator.step this fails.)"""
    import sys
    import threading
    import time

    n = 300_000
    sim = worldgraph.Simulator("multigoal", maze="medium", num_envs=n, seed=0, threads=1)
    actions = np.full(n, 2, dtype=np.uint8)
    samples: list[float] = []
    stop = threading.Event()

    def sampler() -> None:
        while not stop.is_set():
            samples.append(time.perf_counter())

    interval = sys.getswitchinterval()
    sys.setswitchinterval(0.001)
    thread = threading.Thread(target=sampler)
    thread.start()
    steps = []
    try:
        for _ in range(10):
            t0 = time.perf_counter()
            sim.step(actions)
            steps.append((t0, time.perf_counter()))
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(interval)
        sim.close()
    windows = [(a + 0.002, a + (b - a) / 3) for a, b in steps if b - a > 0.012]
    assert windows, "the steps were too short to tell"
    inside = sum(1 for s in samples for a, b in windows if a < s < b)
    assert inside > 0, f"no sample in the first third of {len(windows)} steps"


def run_episode(env: gym.Env, seed: int = 0) -> tuple[int, dict]:
    """Steps `env` with sampled actions until its episode ends; returns the
    steps taken and the last info."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for t in range(1, 100_000):
        _, _, term, trunc, info = env.step(env.action_space.sample())
        if term or trunc:
            return t, info
    raise AssertionError("the episode never ended")


def test_record_episode_statistics_rounds_full_episodes() -> None:
    env = gym.wrappers.RecordEpisodeStatistics(gym.make("worldgraph/MultiGoal-Small-v0", max_steps=40))
    returns = []
    for seed in range(3):
        steps, info = run_episode(env, seed)
        assert info["episode"]["l"] == steps and info["balls"] >= 0
        returns.append(info["episode"]["r"])
    assert list(env.length_queue) == [40, 40, 40] or len(env.length_queue) == 3
    assert list(env.return_queue) == pytest.approx(returns)
    # The vector wrapper over the vector env, same-step auto-reset.
    envs = gym.wrappers.vector.RecordEpisodeStatistics(gym.make_vec("worldgraph/MultiGoal-Small-v0", num_envs=3, max_steps=10))
    envs.reset(seed=0)
    for _ in range(25):
        _, _, term, trunc, info = envs.step(np.zeros(3, dtype=np.int64))
    assert list(envs.length_queue) == [10] * 6


def test_time_limit_and_flatten_observation_round_full_episodes() -> None:
    env = gym.wrappers.TimeLimit(gym.make("worldgraph/MultiGoal-Small-v0"), max_episode_steps=7)
    for seed in range(2):
        steps, _ = run_episode(env, seed)
        assert steps <= 7
    flat = gym.wrappers.FlattenObservation(gym.make("worldgraph/DoorKey-Small-v0", max_steps=30))
    obs, _ = flat.reset(seed=0)
    assert obs.shape == (4 + 13 * 13,) and obs in flat.observation_space
    steps, _ = run_episode(flat)
    assert steps == 30
    obs, _ = flat.reset(seed=1)
    assert obs in flat.observation_space


def test_stepping_a_finished_episode_raises_reset_needed() -> None:
    """Gymnasium leaves a step after the end undefined; here it is refused,
    so an episode is never recorded twice."""
    env = gym.wrappers.RecordEpisodeStatistics(gym.make("worldgraph/Custom-v0", layout=EXIT_AHEAD))
    env.reset(seed=0)
    _, _, term, _, _ = env.step(worldgraph.ACTIONS["forward"])
    assert term
    with pytest.raises(gym.error.ResetNeeded, match=r"the episode ended \(terminated\); call reset\(\)"):
        env.step(worldgraph.ACTIONS["forward"])
    assert env.episode_count == 1
    env.reset()
    env.step(worldgraph.ACTIONS["left"])  # a reset makes it steppable again
    truncating = gym.make("worldgraph/Custom-v0", layout=EXIT_AHEAD, max_steps=1)
    truncating.reset(seed=0)
    assert truncating.step(worldgraph.ACTIONS["left"])[3]
    with pytest.raises(gym.error.ResetNeeded, match=r"\(truncated\)"):
        truncating.step(worldgraph.ACTIONS["left"])
    # Gymnasium's own auto-reset wrapper and SyncVectorEnv still work over it.
    auto = gym.wrappers.Autoreset(gym.make("worldgraph/Custom-v0", layout=EXIT_AHEAD))
    auto.reset(seed=0)
    for t in range(6):
        _, _, term, _, _ = auto.step(worldgraph.ACTIONS["forward"])
        assert term == (t % 2 == 0)
    sync = gym.make_vec("worldgraph/Custom-v0", num_envs=2, vectorization_mode="sync", layout=EXIT_AHEAD)
    sync.reset(seed=0)
    for t in range(6):
        _, _, term, _, _ = sync.step(np.full(2, worldgraph.ACTIONS["forward"]))
        assert term.tolist() == [t % 2 == 0] * 2


def test_envs_refuse_pickling_and_copying_with_a_clear_error() -> None:
    import copy
    import pickle

    env = gym.make("worldgraph/MultiGoal-Small-v0")
    envs = gym.make_vec("worldgraph/MultiGoal-Small-v0", num_envs=2)
    sim = worldgraph.Simulator("multigoal", maze="small")
    for obj, name in ((env, "WorldGraphEnv"), (envs, "WorldGraphVectorEnv"), (sim, "Simulator")):
        for attempt in (pickle.dumps, copy.deepcopy):
            with pytest.raises(TypeError, match=rf"{name} cannot be pickled or copied"):
                attempt(obj)
        # (copy.copy of a Gymnasium wrapper copies the wrapper alone, sharing the env.)
        with pytest.raises(TypeError, match=rf"{name} cannot be pickled or copied"):
            copy.copy(getattr(obj, "unwrapped", obj))


@pytest.mark.parametrize("name", ["LayoutError", "PlanError", "ClosedError", "DoorClosedError"])
def test_the_exceptions_pickle_and_live_in_the_worldgraph_module(name: str) -> None:
    import pickle

    cls = getattr(worldgraph, name)
    assert cls.__module__ == "worldgraph"
    again = pickle.loads(pickle.dumps(cls("why")))
    assert type(again) is cls and str(again) == "why"
    with pytest.raises(cls):
        raise again


def test_close_from_another_thread_waits_for_the_step_in_progress() -> None:
    import threading
    import time

    n = 200_000
    envs = worldgraph.WorldGraphVectorEnv(n, task="multigoal", maze="medium", threads=1)
    envs.reset(seed=0)
    actions = np.full(n, 2, dtype=np.uint8)
    outcomes: list[object] = []
    started = threading.Event()

    def stepper() -> None:
        try:
            for _ in range(1000):
                started.set()
                envs.step(actions)
            outcomes.append("finished")
        except Exception as e:  # noqa: BLE001 - the test inspects it
            outcomes.append(e)

    thread = threading.Thread(target=stepper)
    thread.start()
    started.wait()
    time.sleep(0.01)
    envs.close()  # waits for the step in progress, then closes
    thread.join()
    assert envs.closed and len(outcomes) == 1
    assert isinstance(outcomes[0], ClosedEnvironmentError), outcomes[0]
    # Two threads stepping one simulator take turns instead of failing.
    sim = worldgraph.Simulator("multigoal", maze="medium", num_envs=n, threads=1)
    errors: list[Exception] = []

    def step_some() -> None:
        try:
            for _ in range(5):
                sim.step(actions)
                _ = sim.closed, sim.seed, sim.agent
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    threads = [threading.Thread(target=step_some) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
