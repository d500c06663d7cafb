"""Type stubs of the native module ``worldgraph._worldgraph`` (PyO3).

The Gymnasium classes in :mod:`worldgraph.envs` wrap :class:`Simulator`;
:mod:`worldgraph.graph` wraps :class:`WorldGraph`. Integer arguments out of
range raise ``ValueError`` naming the argument and its limits; NumPy
integers are accepted wherever an ``int`` is.
"""

import os
from collections.abc import Iterator
from typing import Any

import numpy as np
import numpy.typing as npt

class LayoutError(ValueError):
    """A maze layout was refused; the message names the line and column."""

class ClosedError(RuntimeError):
    """The simulator was closed; create a new one."""

class PlanError(ValueError):
    """A world graph could not be loaded, built or queried (unknown node, no route, ...)."""

class DoorClosedError(PlanError):
    """A route passes a door that is closed or locked in the world the query
    describes: a route through a door is refused while the door is closed
    (open it and ask again)."""

def maze_text(maze: str, door_key: bool = False) -> str:
    """The ASCII text of an embedded maze (``small``, ``medium``, ``large``;
    ``door_key``: its Door-Key variant)."""

def check_layout(text: str) -> tuple[int, int]:
    """Parses and validates an ASCII layout; returns ``(width, height)`` or
    raises :class:`LayoutError` naming the line and column. Leading blank
    lines and a common indentation (a triple-quoted string) are set aside;
    errors count lines and columns of the text as given. At most 64×64
    cells."""

def standable_cells(
    task: str = "multigoal", maze: str | None = None, layout: str | None = None
) -> list[tuple[int, int]]:
    """The cells ``(x, y)`` a world-graph node may occupy in a task's maze or
    layout (floor, doors, exits reachable from the start, doors counted
    passable): the cells :meth:`WorldGraph.build` accepts."""

class Simulator:
    """A batch of maze environments stepped in parallel into NumPy arrays.

    Every array attribute is allocated once and rewritten in place by
    :meth:`reset` and :meth:`step` (its buffer never moves): copy what you
    keep. Environment ``i`` draws from its own stream seeded by
    ``(seed, i)``, so results never depend on ``threads``. Thread-safe:
    calls from several threads take turns (``close`` waits for a step in
    progress). Cannot be pickled or copied.
    """

    def __init__(
        self,
        task: str,
        maze: str | None = None,
        layout: str | None = None,
        num_envs: int = 1,
        seed: int = 0,
        threads: int = 1,
        max_steps: int | None = None,
        balls: int | None = None,
        autoreset: bool = True,
    ) -> None:
        """``num_envs`` environments of ``task`` (``multigoal``,
        ``multigoal-sparse``, ``multigoal-stochastic``, ``doorkey``) on an
        embedded ``maze`` or an ASCII ``layout``; already reset. ``threads``
        (at least 1) is capped at the cores; ``seed`` 0 to 2**64 - 1,
        ``max_steps`` 1 to 2**32 - 1, ``balls`` 0 to 255."""
    def reset(self, seed: int | None = None) -> None:
        """Starts a new episode everywhere; ``seed`` (0 to 2**64 - 1)
        re-seeds the batch first."""
    def step(self, actions: npt.ArrayLike) -> int:
        """Steps environment ``i`` with ``actions[i]`` (GIL released); returns
        how many episodes ended. Raises ``ValueError`` for a wrong shape or an
        out-of-range action, ``TypeError`` for a non-integer array."""
    def render(self, index: int = 0, cell_px: int = 16) -> npt.NDArray[np.uint8]:
        """An RGB frame ``(height·cell_px, width·cell_px, 3)`` of environment
        ``index``; ``cell_px`` 2 to 64."""
    def close(self) -> None:
        """Releases the environments (after a step in progress in another
        thread); later calls raise :class:`ClosedError`."""
    @property
    def closed(self) -> bool: ...
    @property
    def num_envs(self) -> int: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def num_actions(self) -> int:
        """3 for the MultiGoal tasks, 6 for Door-Key."""
    @property
    def task(self) -> str: ...
    @property
    def max_steps(self) -> int: ...
    @property
    def threads(self) -> int:
        """Threads stepping the batch: the number asked for, capped at the cores."""
    @property
    def seed(self) -> int: ...
    @property
    def layout_text(self) -> str: ...
    @property
    def layout_name(self) -> str: ...
    @property
    def grid(self) -> npt.NDArray[np.uint8]:
        """``(num_envs, height, width)`` cell codes of the observations."""
    @property
    def agent(self) -> npt.NDArray[np.uint8]:
        """``(num_envs, 4)``: x, y, dir, carried object's code (255: nothing)."""
    @property
    def final_grid(self) -> npt.NDArray[np.uint8]:
        """``(num_envs, height, width)``: the grid each episode the last step ended ended on."""
    @property
    def final_agent(self) -> npt.NDArray[np.uint8]:
        """``(num_envs, 4)``: the pose the last action led to, before any auto-reset."""
    @property
    def reward(self) -> npt.NDArray[np.float32]: ...
    @property
    def terminated(self) -> npt.NDArray[np.bool_]: ...
    @property
    def truncated(self) -> npt.NDArray[np.bool_]: ...
    @property
    def episode_return(self) -> npt.NDArray[np.float32]: ...
    @property
    def episode_length(self) -> npt.NDArray[np.uint32]: ...
    @property
    def balls(self) -> npt.NDArray[np.uint8]: ...

class Route:
    """A planned route: ``actions[i]`` (MiniGrid numbering) leaves the agent
    on ``cells[i]``; ``nodes`` are the graph nodes passed, first to target.
    A value: equal routes compare equal and hash alike; iterating gives the
    actions; routes pickle."""

    def __init__(
        self,
        start: tuple[int, int, int],
        actions: list[int],
        cells: list[tuple[int, int]],
        nodes: list[int],
    ) -> None:
        """A route from its parts (as pickling rebuilds it)."""
    @property
    def start(self) -> tuple[int, int, int]:
        """``(x, y, dir)`` the route starts from."""
    @property
    def actions(self) -> list[int]: ...
    @property
    def cells(self) -> list[tuple[int, int]]: ...
    @property
    def nodes(self) -> list[int]: ...
    def __len__(self) -> int: ...
    def __iter__(self) -> Iterator[int]: ...
    def __eq__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...

class WorldGraph:
    """Pivotal states (nodes), edges with recorded action paths, and
    all-pairs shortest paths (the planner's dynamic programme). Immutable;
    pickles (as its JSON text).

    One graph per maze serves every task on it: a graph built here finds
    its edges with every door open, and a route query given the observed
    ``grid`` raises :class:`DoorClosedError` while a door on the route is
    closed or locked."""

    @staticmethod
    def load(path: str | os.PathLike[str]) -> WorldGraph:
        """A graph saved by the planner (a discover run's ``graph.json``)."""
    @staticmethod
    def from_json(text: str) -> WorldGraph:
        """A graph from the JSON text :meth:`to_json` (or ``save``) writes."""
    def to_json(self) -> str:
        """The graph as the JSON text ``save`` writes."""
    @staticmethod
    def build(
        nodes: npt.ArrayLike,
        task: str = "multigoal",
        maze: str | None = None,
        layout: str | None = None,
        seed: int = 0,
        exhaustive: bool = False,
    ) -> WorldGraph:
        """The graph over the given node cells ``[(x, y), ...]`` of a maze or
        layout, node ``i`` on ``nodes[i]``; a cell no node may occupy (see
        :func:`standable_cells`), a duplicate or a cell outside the grid
        raises :class:`PlanError`."""
    def save(self, path: str | os.PathLike[str]) -> None: ...
    @property
    def num_nodes(self) -> int: ...
    @property
    def nodes(self) -> list[tuple[int, int]]:
        """The nodes (pivotal states) ``(x, y)`` by node id."""
    @property
    def edges(self) -> list[tuple[int, int, int]]:
        """``(from, to, weight)``."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def layout_text(self) -> str: ...
    @property
    def layout_name(self) -> str: ...
    @property
    def task(self) -> str: ...
    def node_at(self, x: int, y: int) -> int | None:
        """The node on cell ``(x, y)``, or None (also outside the grid)."""
    def distance(self, a: int, b: int) -> int | None:
        """Shortest distance from node ``a`` to node ``b``, or None."""
    def route(
        self,
        start: int,
        target: int,
        facing: int = 0,
        grid: npt.ArrayLike | None = None,
        carrying: int = 255,
    ) -> Route:
        """Node-to-node route, standing on ``start`` facing ``facing`` (0 to
        3), in the observed world (``grid``: the observation's ``height ×
        width`` cell codes, or flat; ``carrying``) or the graph's own;
        :class:`DoorClosedError` when it enters a door ``grid`` shows
        closed."""
    def route_from_pose(
        self,
        x: int,
        y: int,
        dir: int,
        target: int,
        grid: npt.ArrayLike | None = None,
        carrying: int = 255,
    ) -> Route:
        """Route from any pose to node ``target``, in the observed world
        (``grid``, ``carrying``: door states and the key in hand; the walls
        are the graph's layout's) or the graph's own;
        :class:`DoorClosedError` when it enters a door ``grid`` shows
        closed."""
    def render(self, cell_px: int = 16) -> npt.NDArray[np.uint8]:
        """The maze with the graph drawn on it; ``cell_px`` 2 to 64."""
    def __reduce__(self) -> tuple[Any, tuple[str]]: ...
