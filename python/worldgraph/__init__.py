"""worldgraph: MiniGrid-rules mazes and world graphs (Shang et al. 2019) for Python.

Gymnasium environments over worldgraph's Rust maze simulator, registered on
import::

    import gymnasium as gym
    import worldgraph  # registers the ids

    envs = gym.make_vec("worldgraph/MultiGoal-Small-v0", num_envs=1024)
    env = gym.make("worldgraph/DoorKey-Medium-v0", render_mode="rgb_array")
    custom = gym.make("worldgraph/Custom-v0", layout=open("my.txt").read(), task="multigoal")

Ids: ``worldgraph/{Task}-{Maze}-v0`` for Task in MultiGoal, MultiGoalSparse,
MultiGoalStochastic, DoorKey and Maze in Small, Medium, Large, plus
``worldgraph/Custom-v0`` (keyword ``layout``: ASCII text; ``task``).

The world graph: :func:`load_discover_run`, :class:`WorldGraph` (nodes,
``route``, ``route_from_pose``), :func:`replay_route`, :func:`standable_cells`.

Errors: :class:`LayoutError`, :class:`PlanError` and its
:class:`DoorClosedError` (``ValueError`` subclasses), :class:`ClosedError`; all
importable from ``worldgraph`` (and so picklable).
"""

from __future__ import annotations

import gymnasium as gym

from ._worldgraph import (
    ClosedError,
    DoorClosedError,
    LayoutError,
    PlanError,
    Simulator,
    check_layout,
    maze_text,
    standable_cells,
)
from .envs import ACTIONS, CARRYING_NOTHING, CELL_PX, NUM_OBJECTS, OBJECTS, WorldGraphEnv, WorldGraphVectorEnv, observation_space
from .graph import Replay, Route, WorldGraph, load_discover_run, pivotal_states, replay_route

__all__ = [
    "ACTIONS",
    "CARRYING_NOTHING",
    "CELL_PX",
    "CUSTOM_ID",
    "ClosedError",
    "DoorClosedError",
    "ENV_IDS",
    "LayoutError",
    "MAZES",
    "NUM_OBJECTS",
    "OBJECTS",
    "PlanError",
    "Replay",
    "Route",
    "Simulator",
    "TASKS",
    "WorldGraph",
    "WorldGraphEnv",
    "WorldGraphVectorEnv",
    "check_layout",
    "load_discover_run",
    "maze_text",
    "observation_space",
    "pivotal_states",
    "register_envs",
    "replay_route",
    "standable_cells",
]

__version__ = "0.1.0"

#: Task name in ids -> the simulator's task name.
TASKS = {
    "MultiGoal": "multigoal",
    "MultiGoalSparse": "multigoal-sparse",
    "MultiGoalStochastic": "multigoal-stochastic",
    "DoorKey": "doorkey",
}
#: Maze name in ids -> the simulator's maze name.
MAZES = {"Small": "small", "Medium": "medium", "Large": "large"}

#: A small room, the default layout of ``worldgraph/Custom-v0``.
DEFAULT_CUSTOM_LAYOUT = "#######\n#>....#\n#.....#\n#..#..#\n#....E#\n#######\n"

CUSTOM_ID = "worldgraph/Custom-v0"
#: Every registered id.
ENV_IDS = [f"worldgraph/{t}-{m}-v0" for t in TASKS for m in MAZES] + [CUSTOM_ID]


def register_envs() -> None:
    """Registers every id with Gymnasium (done on import; idempotent)."""
    for t, task in TASKS.items():
        for m, maze in MAZES.items():
            env_id = f"worldgraph/{t}-{m}-v0"
            if env_id in gym.registry:
                continue
            gym.register(
                id=env_id,
                entry_point="worldgraph.envs:WorldGraphEnv",
                vector_entry_point="worldgraph.envs:WorldGraphVectorEnv",
                kwargs={"task": task, "maze": maze},
            )
    if CUSTOM_ID not in gym.registry:
        gym.register(
            id=CUSTOM_ID,
            entry_point="worldgraph.envs:WorldGraphEnv",
            vector_entry_point="worldgraph.envs:WorldGraphVectorEnv",
            kwargs={"task": "multigoal", "maze": None, "layout": DEFAULT_CUSTOM_LAYOUT},
        )


register_envs()
