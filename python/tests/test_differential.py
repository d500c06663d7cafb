"""The Python vector env against the Rust simulator stepped directly.

The reference is sim/examples/reference_rollout.rs: N `sim::Env`s stepped
one after another through `Env::step` (no BatchEnv, no threads, no NumPy),
seeded like the batch (environment i from (seed, i)). Random actions, every
task, embedded mazes and a small custom room where random walks reach the
exit; both sides must agree on every observation, reward, flag, final
observation and episode figure, with the Python side on several threads.
"""

from __future__ import annotations

import pathlib
import subprocess

import numpy as np
import pytest

import worldgraph

ROOM = "#######\n#>....#\n#.B...#\n#..#..#\n#...LE#\n#######\n"

META = np.dtype(
    [
        ("reward", "<f4"),
        ("episode_return", "<f4"),
        ("episode_len", "<u4"),
        ("x", "<u2"),
        ("y", "<u2"),
        ("dir", "u1"),
        ("carrying", "u1"),
        ("flags", "u1"),
        ("balls", "u1"),
        ("end_x", "<u2"),
        ("end_y", "<u2"),
        ("end_dir", "u1"),
        ("end_carrying", "u1"),
        ("reserved", "<u2"),
    ]
)
assert META.itemsize == 28
TERMINATED, TRUNCATED = 1, 2


def reference(binary, tmp, task, maze, seed, n, max_steps, actions, hw):
    """Runs the Rust reference; returns (grid, final_grid, meta) per step,
    shaped (T+1, n, ...)."""
    (tmp / "actions.bin").write_bytes(actions.astype(np.uint8).tobytes())
    subprocess.run(
        [str(binary), task, maze, str(seed), str(n), str(max_steps), str(tmp / "actions.bin"), str(tmp / "out.bin")],
        check=True,
    )
    rec = np.dtype([("grid", "u1", (hw,)), ("final", "u1", (hw,)), ("meta", META)])
    out = np.fromfile(tmp / "out.bin", dtype=rec).reshape(len(actions) + 1, n)
    return out["grid"], out["final"], out["meta"]


CASES = [
    # task, maze ("room": ROOM), seed, envs, max_steps (0: the task's default), steps
    ("multigoal", "small", 1, 6, 0, 700),
    ("multigoal-sparse", "small", 2, 6, 60, 400),
    ("multigoal-stochastic", "medium", 3, 5, 80, 400),
    ("doorkey", "small", 4, 6, 50, 400),
    ("multigoal", "room", 5, 8, 40, 400),
    ("multigoal-sparse", "room", 6, 8, 40, 400),
    ("multigoal-stochastic", "room", 7, 8, 40, 400),
    ("doorkey", "room", 8, 8, 40, 400),
]


@pytest.mark.parametrize(("task", "maze", "seed", "n", "max_steps", "steps"), CASES)
def test_the_python_env_steps_like_the_rust_simulator(
    reference_binary: pathlib.Path, tmp_path: pathlib.Path, task, maze, seed, n, max_steps, steps
) -> None:
    custom = maze == "room"
    envs = worldgraph.WorldGraphVectorEnv(
        n,
        task=task,
        maze=None if custom else maze,
        layout=ROOM if custom else None,
        max_steps=max_steps or None,
        threads=3,
    )
    if custom:
        (tmp_path / "layout.txt").write_text(ROOM)
        maze_arg = "@" + str(tmp_path / "layout.txt")
    else:
        maze_arg = maze
    h, w = envs.single_observation_space["grid"].shape
    rng = np.random.default_rng(seed)
    # Forward-heavy random actions, so that walks cover the maze.
    k = envs.single_action_space.n
    p = np.full(k, 0.5 / (k - 1))
    p[2] = 0.5
    actions = rng.choice(k, size=(steps, n), p=p)
    grid, final, meta = reference(reference_binary, tmp_path, task, maze_arg, seed, n, max_steps, actions, h * w)

    obs, _ = envs.reset(seed=seed)
    assert np.array_equal(obs["grid"].reshape(n, -1), grid[0])
    assert np.array_equal(obs["agent"], np.stack([meta[0]["x"], meta[0]["y"], meta[0]["dir"], meta[0]["carrying"]], 1))
    ends = {"terminated": 0, "truncated": 0}
    for t in range(steps):
        obs, rew, term, trunc, info = envs.step(actions[t])
        m = meta[t + 1]
        where = f"{task} on {maze!r}, step {t + 1}"
        assert np.array_equal(obs["grid"].reshape(n, -1), grid[t + 1]), where
        agent = np.stack([m["x"], m["y"], m["dir"], m["carrying"]], 1)
        assert np.array_equal(obs["agent"], agent), where
        assert np.array_equal(rew, m["reward"]), where
        assert np.array_equal(term, (m["flags"] & TERMINATED) != 0), where
        assert np.array_equal(trunc, (m["flags"] & TRUNCATED) != 0), where
        done = term | trunc
        ends["terminated"] += int(term.sum())
        ends["truncated"] += int(trunc.sum())
        if not done.any():
            assert info == {}, where
            continue
        assert np.array_equal(info["_final_obs"], done), where
        for i in np.flatnonzero(done):
            f = info["final_obs"][i]
            assert np.array_equal(f["grid"].reshape(-1), final[t + 1, i]), where
            end = [m["end_x"][i], m["end_y"][i], m["end_dir"][i], m["end_carrying"][i]]
            assert f["agent"].tolist() == end, where
            assert info["final_info"]["episode"]["r"][i] == m["episode_return"][i], where
            assert info["final_info"]["episode"]["l"][i] == m["episode_len"][i], where
            assert info["final_info"]["balls"][i] == m["balls"][i], where
    envs.close()
    # The episodes did end, both ways where the maze allows it.
    assert ends["truncated"] > 0
    if custom:
        assert ends["terminated"] > 0
