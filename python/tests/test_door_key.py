"""The Door-Key world graph from Python follows the project's rule (issue
47): one world graph per maze serves every task on it. Its edges are found
with the doors passable, so routes through a door exist; a route through a
door is refused only while that door is closed in the world the query
describes (`grid`), and taken once it is open."""

from __future__ import annotations

import collections
import pathlib

import gymnasium as gym
import numpy as np
import pytest

import worldgraph

OPEN = {worldgraph.OBJECTS[k] for k in ("floor", "door_open")}

# The small maze's Door-Key variant: its key, door and exit.
KEY, DOOR, EXIT = (9, 2), (6, 9), (11, 11)


def face(env: gym.Env, obs: dict, cell: tuple[int, int]) -> dict:
    """Walks the agent (turns and forward moves over floor and open doors,
    a breadth-first search on the observed grid) to a cell next to `cell`,
    facing it; returns the last observation."""
    grid = obs["grid"]
    start = tuple(int(v) for v in obs["agent"][:3])
    steps = [(1, 0), (0, 1), (-1, 0), (0, -1)]
    parent: dict[tuple[int, int, int], tuple[tuple[int, int, int], int] | None] = {start: None}
    queue = collections.deque([start])
    while queue:
        x, y, d = pose = queue.popleft()
        if (x + steps[d][0], y + steps[d][1]) == cell:
            actions = []
            while parent[pose] is not None:
                pose, a = parent[pose]
                actions.append(a)
            for a in reversed(actions):
                obs, _, term, trunc, _ = env.step(a)
                assert not (term or trunc)
            return obs
        nx, ny = x + steps[d][0], y + steps[d][1]
        for a, nxt in ((0, (x, y, (d + 3) % 4)), (1, (x, y, (d + 1) % 4)), (2, (nx, ny, d))):
            if a == 2 and grid[ny, nx] not in OPEN:
                continue
            if nxt not in parent:
                parent[nxt] = (pose, a)
                queue.append(nxt)
    raise AssertionError(f"no way to face {cell}")


@pytest.mark.parametrize(("maze", "seed"), [("small", 0), ("small", 1), ("small", 2), ("medium", 0), ("medium", 1)])
def test_a_real_discover_runs_door_key_graph_is_one_graph(real_run, maze: str, seed: int) -> None:
    """Every node reaches every other (exit nodes end the episode, so
    nothing leaves them): the door does not split the graph in two."""
    graph = worldgraph.load_discover_run(real_run(maze, seed), task="doorkey")
    assert graph.task == "doorkey" and graph.layout_name == f"{maze}-doorkey"
    n = graph.num_nodes
    layout = worldgraph.maze_text(maze, door_key=True).splitlines()
    exits = {(x, y) for y, row in enumerate(layout) for x, c in enumerate(row) if c == "E"}
    unroutable = [(a, b) for a in range(n) for b in range(n) if graph.distance(a, b) is None and graph.nodes[a] not in exits]
    assert unroutable == []


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_real_discover_runs_door_key_route_goes_through_the_door_once_it_is_open(real_run, seed: int) -> None:
    graph = worldgraph.load_discover_run(real_run("small", seed), task="doorkey")
    env = gym.make("worldgraph/DoorKey-Small-v0")
    obs, _ = env.reset(seed=0)
    n = graph.num_nodes
    target = min(range(n), key=lambda k: abs(graph.nodes[k][0] - EXIT[0]) + abs(graph.nodes[k][1] - EXIT[1]))
    assert graph.nodes[target][0] > DOOR[0] and graph.nodes[target][1] > 6  # in the exit's room
    x, y, d, carrying = obs["agent"]
    # In the graph's own world, with the doors passable, the route exists and goes through the door ...
    route = graph.route_from_pose(x, y, d, target)
    assert DOOR in route.cells
    assert worldgraph.ACTIONS["toggle"] not in route.actions and worldgraph.ACTIONS["pickup"] not in route.actions
    # ... it is refused while the door is locked in the world the agent is in ...
    with pytest.raises(worldgraph.DoorClosedError, match=r"locked door at \(6, 9\)"):
        graph.route_from_pose(x, y, d, target, grid=obs["grid"], carrying=carrying)
    with pytest.raises(worldgraph.DoorClosedError):
        worldgraph.replay_route(env, route)  # refused before a step is taken
    assert env.unwrapped.simulator.agent[0].tolist() == obs["agent"].tolist()
    # ... and taken once the agent has fetched the key and opened the door.
    obs = face(env, obs, KEY)
    obs, *_ = env.step(worldgraph.ACTIONS["pickup"])
    obs = face(env, obs, DOOR)
    obs, reward, *_ = env.step(worldgraph.ACTIONS["toggle"])
    assert obs["grid"][DOOR[1], DOOR[0]] == worldgraph.OBJECTS["door_open"] and reward > 0.9
    x, y, d, carrying = obs["agent"]
    route = graph.route_from_pose(x, y, d, target, grid=obs["grid"], carrying=carrying)
    end = worldgraph.replay_route(env, route)
    assert (end.x, end.y) == graph.nodes[target] and not end.truncated


def test_the_door_key_graph_keeps_the_run_s_pivotal_states_the_door_key_maze_can_hold(real_run) -> None:
    run = real_run("small", 0)
    pivotal = worldgraph.pivotal_states(run)
    free = set(worldgraph.standable_cells(task="doorkey", maze="small"))
    graph = worldgraph.load_discover_run(run, task="doorkey")
    # In the run's order, minus the passage the Door-Key variant walls up;
    # the doorway it puts the door in stays a node (seed 0 has it).
    assert graph.nodes == [c for c in pivotal if c in free]
    assert set(pivotal) - set(graph.nodes) <= {(9, 6)}
    assert DOOR in graph.nodes


def test_a_node_on_the_door_is_reached_once_the_door_is_open() -> None:
    graph = worldgraph.WorldGraph.build([(1, 11), DOOR, (8, 9)], task="doorkey", maze="small")
    env = gym.make("worldgraph/DoorKey-Small-v0")
    obs, _ = env.reset(seed=0)
    assert graph.route(0, 1).cells[-1] == DOOR
    with pytest.raises(worldgraph.DoorClosedError, match=r"locked door at \(6, 9\)"):
        graph.route(0, 1, grid=obs["grid"])
    with pytest.raises(worldgraph.DoorClosedError, match=r"locked door at \(6, 9\)"):
        graph.route(0, 2, grid=obs["grid"])
    opened = obs["grid"].copy()
    opened[DOOR[1], DOOR[0]] = worldgraph.OBJECTS["door_open"]
    assert graph.route(0, 2, grid=opened, carrying=worldgraph.OBJECTS["key"]).nodes == [0, 1, 2]


def test_a_closed_door_blocks_a_route_until_it_is_opened_by_hand() -> None:
    """A custom layout with an unlocked door: the graph crosses it, the route
    is refused while `grid` shows it closed and given once it is open."""
    layout = "#########\n#>..C..E#\n#########\n"
    graph = worldgraph.WorldGraph.build([(2, 1), (6, 1)], task="doorkey", layout=layout)
    assert graph.distance(0, 1) == 4
    env = gym.make("worldgraph/Custom-v0", layout=layout, task="doorkey")
    obs, _ = env.reset(seed=0)
    obs, *_ = env.step(worldgraph.ACTIONS["forward"])  # onto node 0, facing the door
    with pytest.raises(worldgraph.DoorClosedError, match=r"closed door at \(4, 1\)"):
        graph.route(0, 1, facing=0, grid=obs["grid"])
    obs, *_ = env.step(worldgraph.ACTIONS["forward"])
    obs, *_ = env.step(worldgraph.ACTIONS["toggle"])
    obs, *_ = env.step(worldgraph.ACTIONS["left"])
    obs, *_ = env.step(worldgraph.ACTIONS["left"])
    obs, *_ = env.step(worldgraph.ACTIONS["forward"])  # back on node 0, facing away
    route = graph.route(0, 1, facing=int(obs["agent"][2]), grid=obs["grid"])
    assert (4, 1) in route.cells
    end = worldgraph.replay_route(env, route)
    assert (end.x, end.y) == (6, 1)
