"""Arguments as a careful user passes them: integers out of range name the
argument and its limits (a ValueError, never the binding's OverflowError),
NumPy integers are ints, thread counts are checked in Python's words and
capped at the cores, layouts come as triple-quoted strings."""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import worldgraph

SMALL = "worldgraph/MultiGoal-Small-v0"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_steps": -1}, r"max_steps must be an int from 1 to 4294967295, got -1"),
        ({"max_steps": 2**32}, r"max_steps must be an int from 1 to 4294967295, got 4294967296"),
        ({"max_steps": 0}, r"max_steps must be an int from 1"),
        ({"balls": -1}, r"balls must be an int from 0 to 255, got -1"),
        ({"balls": 256}, r"balls must be an int from 0 to 255, got 256"),
        ({"cell_px": -3, "render_mode": "rgb_array"}, r"cell_px must be an int from 2 to 64, got -3"),
        ({"cell_px": 65}, r"cell_px must be an int from 2 to 64, got 65"),
    ],
)
def test_out_of_range_env_arguments_raise_a_value_error_naming_the_argument(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make(SMALL, **kwargs)
    with pytest.raises(ValueError, match=message):
        gym.make_vec(SMALL, num_envs=2, **kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"threads": -1}, r"threads must be an int from 1 to"),
        ({"num_envs": -1}, r"num_envs must be an int from 1 to"),
        ({"seed": -1}, r"seed must be an int from 0 to 18446744073709551615, got -1"),
        ({"seed": 2**64}, r"seed must be an int from 0 to 18446744073709551615, got 18446744073709551616"),
        ({"max_steps": 2**200}, r"max_steps must be an int from 1 to 4294967295$"),
    ],
)
def test_the_native_simulator_names_the_argument_out_of_range(kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        worldgraph.Simulator("multigoal", maze="small", **kwargs)


def test_render_arguments_out_of_range_name_the_argument() -> None:
    sim = worldgraph.Simulator("multigoal", maze="small", num_envs=2)
    with pytest.raises(ValueError, match=r"index must be an int from 0 to 1, got -1"):
        sim.render(-1)
    with pytest.raises(ValueError, match=r"index must be an int from 0 to 1, got 2"):
        sim.render(2)
    with pytest.raises(ValueError, match=r"cell_px must be an int from 2 to 64, got -3"):
        sim.render(0, cell_px=-3)
    graph = worldgraph.WorldGraph.build([(1, 11), (3, 9)], maze="small")
    for bad in (-1, 0, 10**6):
        # 10**6 pixels a cell used to abort the interpreter allocating the canvas.
        with pytest.raises(ValueError, match=rf"cell_px must be an int from 2 to 64, got {bad}"):
            graph.render(bad)


def test_seeds_out_of_range_raise_a_value_error_naming_seed() -> None:
    env = gym.make(SMALL)
    with pytest.raises(ValueError, match=r"seed must be an int from 0 to 18446744073709551615"):
        env.reset(seed=2**64)
    env.reset(seed=2**64 - 1)
    envs = gym.make_vec(SMALL, num_envs=2)
    with pytest.raises(ValueError, match=r"seed must be an int from 0 to 18446744073709551615"):
        envs.reset(seed=2**64)
    with pytest.raises(ValueError, match=r"seed must be an int from 0 to 18446744073709551615, got -1"):
        envs.reset(seed=-1)
    sim = worldgraph.Simulator("multigoal", maze="small")
    with pytest.raises(ValueError, match=r"seed must be an int from 0"):
        sim.reset(seed=2**64)
    with pytest.raises(ValueError, match=r"seed must be an int from 0"):
        worldgraph.WorldGraph.build([(1, 11)], maze="small", seed=-1)


@pytest.mark.parametrize("seed", [np.int64(3), np.uint64(3), np.int8(3)])
def test_numpy_integer_seeds_are_ints(seed) -> None:
    """Gymnasium's own checks allow `np.integer` seeds; its seeding does not,
    so the envs turn them into ints first."""
    envs = gym.make_vec(SMALL, num_envs=2)
    a, _ = envs.reset(seed=seed)
    a = {k: v.copy() for k, v in a.items()}
    b, _ = envs.reset(seed=3)
    assert np.array_equal(a["grid"], b["grid"]) and np.array_equal(a["agent"], b["agent"])
    env = gym.make(SMALL)
    c, _ = env.reset(seed=seed)
    d, _ = env.reset(seed=3)
    assert np.array_equal(c["grid"], d["grid"])
    assert np.array_equal(c["grid"], b["grid"][0])


def test_thread_counts_are_checked_in_python_words_and_capped_at_the_cores() -> None:
    for bad in (0, -1):
        with pytest.raises(ValueError, match=r"^threads must be an int from 1 to") as caught:
            gym.make_vec(SMALL, num_envs=2, threads=bad)
        assert "--threads" not in str(caught.value)
    envs = gym.make_vec(SMALL, num_envs=2, threads=1000)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert envs.unwrapped.simulator.threads == min(1000, cores)
    envs.close()
    assert worldgraph.Simulator("multigoal", maze="small", threads=1000).threads == cores


def test_an_action_too_large_for_any_integer_type_is_out_of_range() -> None:
    env = gym.make(SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action 1180591620717411303424 of environment 0 is out of range"):
        env.step(2**70)
    envs = gym.make_vec(SMALL, num_envs=2)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"of environment 1 is out of range"):
        envs.step([0, 2**70])


LEADING_NEWLINE = """
#####
#>.E#
#####
"""


def indented() -> str:
    layout = """
        #######
        #>..B.#
        #....E#
        #######
    """
    return layout


@pytest.mark.parametrize("text", [LEADING_NEWLINE, indented(), "\n\n  ####\n  #>E#\n  ####\n  \n"])
def test_triple_quoted_layouts_are_accepted(text: str) -> None:
    env = gym.make("worldgraph/Custom-v0", layout=text)
    check_env(env.unwrapped)
    obs, _ = env.reset(seed=0)
    assert obs["agent"][:2].tolist() == [1, 1]
    sim = env.unwrapped.simulator
    assert worldgraph.check_layout(text) == (sim.width, sim.height)
    graph = worldgraph.WorldGraph.build([(1, 1)], layout=text)
    assert graph.num_nodes == 1


def test_errors_in_a_triple_quoted_layout_name_the_line_and_column_as_written() -> None:
    # Line 1 is the empty line after the opening quotes; the bad cell is on
    # line 3 of the string, column 11 counting the indentation.
    text = """
        #####
        #>x.#
        #..E#
        #####
    """
    with pytest.raises(worldgraph.LayoutError, match=r"line 3, column 11"):
        gym.make("worldgraph/Custom-v0", layout=text)
    with pytest.raises(worldgraph.LayoutError, match=r"ragged row: line 4"):
        worldgraph.check_layout("\n#####\n#>.E#\n####\n#####\n")
    with pytest.raises(worldgraph.LayoutError, match=r"a second agent at line 4, column 3; the first is at line 3, column 2"):
        worldgraph.check_layout("\n#####\n#>.E#\n#.>.#\n#####\n")
    with pytest.raises(worldgraph.LayoutError, match=r"the layout is empty"):
        worldgraph.check_layout("\n   \n\n")


def test_the_64_cell_limit_is_a_layout_error() -> None:
    wall = "#" * 65
    text = f"{wall}\n#>{'.' * 61}E#\n{wall}\n"
    with pytest.raises(worldgraph.LayoutError, match=r"at most 64x64 cells"):
        gym.make("worldgraph/Custom-v0", layout=text)


def test_unsupported_render_modes_are_refused_by_the_env() -> None:
    with pytest.raises(ValueError, match="render_mode"):
        worldgraph.WorldGraphEnv(render_mode="human")
    with pytest.raises(ValueError, match="render_mode"):
        worldgraph.WorldGraphVectorEnv(2, render_mode="human")


@pytest.mark.skipif(not os.path.exists("/proc/meminfo"), reason="the memory check reads Linux's /proc/meminfo")
def test_a_batch_larger_than_the_memory_is_a_memory_error_not_an_abort() -> None:
    with pytest.raises(MemoryError, match=r"num_envs=1000000000 needs about \d+\.\d GB"):
        worldgraph.Simulator("multigoal", maze="small", num_envs=10**9)
    with pytest.raises(MemoryError):
        gym.make_vec(SMALL, num_envs=10**9)
