"""The world graph from Python: load a ``worldgraph discover`` run, list its
pivotal states, plan routes by the planner's dynamic programme, replay them.

A discover run directory holds ``graph.json`` (the world graph over the
pivotal states ``V_p``, the planner's format), ``pivotal.json`` (the pivotal
states as ``[[x, y], ...]``) and ``config.toml``, among others.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gymnasium.error import ResetNeeded

from . import _worldgraph as _native
from .envs import OBJECTS

if TYPE_CHECKING:
    from .envs import WorldGraphEnv

WorldGraph = _native.WorldGraph
Route = _native.Route


def pivotal_states(run_dir: str | os.PathLike[str]) -> list[tuple[int, int]]:
    """The pivotal states ``(x, y)`` a discover run found (its ``pivotal.json``,
    else its graph's nodes)."""
    path = os.path.join(run_dir, "pivotal.json")
    if os.path.exists(path):
        with open(path) as f:
            cells = json.load(f)
        if not isinstance(cells, list) or not all(
            isinstance(c, list) and len(c) == 2 and all(isinstance(v, int) for v in c) for c in cells
        ):
            raise _native.PlanError(f"{path}: expected a list of [x, y] pairs")
        return [(c[0], c[1]) for c in cells]
    return load_discover_run(run_dir).nodes


def load_discover_run(
    run_dir: str | os.PathLike[str], task: str | None = None, seed: int = 0, exhaustive: bool = False
) -> _native.WorldGraph:
    """The world graph of a ``worldgraph discover`` run directory.

    Without ``task`` (or for a MultiGoal task), the run's ``graph.json`` as
    discovered. For ``task="doorkey"``, the graph of the maze's Door-Key
    variant over the run's pivotal states: the states that variant can hold
    (``standable_cells``; the passage it walls up is left out), in the run's
    order, with edges built again by :meth:`WorldGraph.build` (random walks
    seeded by ``seed``, or with ``exhaustive`` a search over states;
    shortened by an exact search instead of by ``π_g``, which needs
    libtorch). One world graph per maze serves every task on it: the edges
    are found with the door passable, so routes through the door exist; a
    route query given the observed ``grid`` raises
    :class:`worldgraph.DoorClosedError` while the door is closed or locked,
    and returns the route once it is open.
    """
    path = os.path.join(run_dir, "graph.json")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: not a discover run directory (no graph.json)")
    graph = _native.WorldGraph.load(path)
    if task is None or task.replace("_", "-").lower() not in ("doorkey", "door-key"):
        return graph
    maze = graph.layout_name
    if maze not in ("small", "medium", "large"):
        raise _native.PlanError(
            f"the run's layout {maze!r} is not an embedded maze: build its Door-Key graph with "
            "WorldGraph.build(nodes, task='doorkey', layout=...)"
        )
    # WorldGraph.build refuses cells no node may occupy: leave them out here.
    free = set(_native.standable_cells(task="doorkey", maze=maze))
    nodes = [c for c in pivotal_states(run_dir) if c in free]
    return _native.WorldGraph.build(nodes, task="doorkey", maze=maze, seed=seed, exhaustive=exhaustive)


@dataclass
class Replay:
    """What replaying a route did: the pose after the last action, the
    reward collected, and whether the episode ended on the way."""

    x: int
    y: int
    dir: int
    reward: float
    terminated: bool
    truncated: bool
    steps: int


def replay_route(env: WorldGraphEnv, route: _native.Route) -> Replay:
    """Steps ``env`` (a :class:`worldgraph.WorldGraphEnv`, possibly wrapped,
    standing at the route's start: plan from its pose with
    :meth:`WorldGraph.route_from_pose`) through the route's actions,
    stopping early if the episode ends, and checks that each step lands on
    the cell the route predicted.

    Before any step, raises ``ValueError`` when the agent is not at the
    route's start and :class:`worldgraph.DoorClosedError` when the route
    enters a door that is closed or locked now; ``gymnasium.error.ResetNeeded``
    when the env was never reset. A step landing elsewhere than predicted
    (a world other than the one the route was planned in) raises
    :class:`worldgraph.PlanError` naming the step.
    """
    sim = env.unwrapped.simulator
    if not env.unwrapped._seeded:
        raise ResetNeeded("reset() the env before replaying a route in it")
    x, y, d = (int(v) for v in sim.agent[0][:3])
    if (x, y, d) != tuple(route.start):
        raise ValueError(
            f"the agent is at {(x, y, d)} but the route starts at {tuple(route.start)}: "
            "plan the route from the agent's pose (WorldGraph.route_from_pose)"
        )
    grid = sim.grid[0]
    for cx, cy in route.cells:
        code = int(grid[cy, cx])
        if code in (OBJECTS["door_closed"], OBJECTS["door_locked"]):
            kind = "locked" if code == OBJECTS["door_locked"] else "closed"
            raise _native.DoorClosedError(
                f"the route passes the {kind} door at ({cx}, {cy}), {kind} in the env: a route through "
                "a door is refused while the door is closed; open it and plan again"
            )
    total, term, trunc, steps = 0.0, False, False, 0
    for i, (a, cell) in enumerate(zip(route.actions, route.cells)):
        obs, r, term, trunc, _ = env.step(a)
        total += r
        steps += 1
        if term or trunc:
            break
        got = (int(obs["agent"][0]), int(obs["agent"][1]))
        if got != tuple(cell):
            raise _native.PlanError(
                f"step {i} of the route: the agent is at {got}, the route expected {tuple(cell)} "
                "(the world is not the one the route was planned in)"
            )
    # The single env does not auto-reset: its agent is where the last action left it.
    x, y, d = (int(v) for v in sim.agent[0][:3])
    return Replay(x, y, d, total, term, trunc, steps)
