"""The world graph from Python: a discover run loaded, its pivotal states,
routes planned by the planner's dynamic programme and replayed in an env."""

from __future__ import annotations

import json
import pathlib

import gymnasium as gym
import numpy as np
import pytest

import worldgraph


def test_a_discover_run_loads_with_its_pivotal_states(discover_run: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    cells = [tuple(c) for c in json.loads((discover_run / "pivotal.json").read_text())]
    assert worldgraph.pivotal_states(discover_run) == cells
    assert graph.nodes == cells  # every pivotal state of the small maze is a node
    assert graph.num_nodes == len(cells) and graph.layout_name == "small"
    assert (graph.width, graph.height) == (13, 13)
    assert len(graph.edges) > graph.num_nodes
    for a, b, weight in graph.edges:
        assert graph.distance(a, b) <= weight
    x, y = cells[3]
    assert graph.node_at(x, y) == 3 and graph.node_at(0, 0) is None
    assert graph.render(8).shape == (13 * 8, 13 * 8, 3)


def farthest_pair(graph: worldgraph.WorldGraph) -> tuple[int, int]:
    best = (0, 0, -1)
    for a in range(graph.num_nodes):
        for b in range(graph.num_nodes):
            d = graph.distance(a, b)
            if d is not None and d > best[2]:
                best = (a, b, d)
    return best[0], best[1]


def test_a_route_between_two_cells_replays_to_its_target(discover_run: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    a, b = farthest_pair(graph)
    env = gym.make("worldgraph/MultiGoal-Small-v0", balls=0)
    obs, _ = env.reset(seed=0)
    x, y, d, _ = (int(v) for v in obs["agent"])
    # From the start pose to node a, then node a to node b.
    to_a = graph.route_from_pose(x, y, d, a)
    assert to_a.nodes[-1] == a and to_a.start == (x, y, d)
    at_a = worldgraph.replay_route(env, to_a)
    assert (at_a.x, at_a.y) == graph.nodes[a] and not at_a.terminated
    to_b = graph.route(a, b, facing=at_a.dir)
    assert to_b.nodes[0] == a and to_b.nodes[-1] == b and len(to_b.nodes) >= 2
    assert len(to_b) >= graph.distance(a, b)  # edge actions plus the turns between edges
    at_b = worldgraph.replay_route(env, to_b)
    assert (at_b.x, at_b.y) == graph.nodes[b]
    assert at_b.steps == len(to_b) and at_b.reward == pytest.approx(-0.01 * len(to_b))


def test_planning_errors_are_python_exceptions(discover_run: pathlib.Path, tmp_path: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    with pytest.raises(worldgraph.PlanError, match="unknown node"):
        graph.route(0, graph.num_nodes)
    with pytest.raises(worldgraph.PlanError, match="unknown node"):
        graph.distance(-1, 0)
    with pytest.raises(worldgraph.PlanError):
        graph.route_from_pose(0, 0, 0, 0)  # a wall: no way onto the graph
    with pytest.raises(FileNotFoundError, match="no graph.json"):
        worldgraph.load_discover_run(tmp_path)
    (tmp_path / "graph.json").write_text('{"format": "something else"}')
    with pytest.raises(worldgraph.PlanError):
        worldgraph.load_discover_run(tmp_path)
    with pytest.raises(worldgraph.PlanError, match="outside"):
        worldgraph.WorldGraph.build([(40, 1)], maze="small")


def test_a_graph_round_trips_through_its_file(discover_run: pathlib.Path, tmp_path: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    graph.save(tmp_path / "g.json")
    again = worldgraph.WorldGraph.load(tmp_path / "g.json")
    assert again.nodes == graph.nodes and again.edges == graph.edges
    a, b = farthest_pair(graph)
    assert again.route(a, b).actions == graph.route(a, b).actions
    assert np.array_equal(again.render(4), graph.render(4))


def test_a_real_discover_run_loads_and_routes(worldgraph_binary: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """A run written by `worldgraph discover` itself (one short round, a few
    seconds), not one shaped like it: its graph.json and pivotal.json load,
    and a route over its graph replays to its target."""
    import os
    import subprocess

    run = tmp_path / "discover"
    subprocess.run(
        [str(worldgraph_binary), "discover", "--maze", "small", "--run", str(run), "--rounds", "1",
         "--gcp-iters", "2", "--envs", "16", "--seed", "3"],
        check=True,
        capture_output=True,
        env={**os.environ, "WORLDGRAPH_TORCH_THREADS": "1"},
    )
    graph = worldgraph.load_discover_run(run)
    assert graph.layout_name == "small" and graph.num_nodes > 1
    # Every node is a pivotal state (cells the agent cannot stand on are not nodes).
    assert set(graph.nodes) <= set(worldgraph.pivotal_states(run))
    a, b = farthest_pair(graph)
    env = gym.make("worldgraph/MultiGoal-Small-v0", balls=0)
    obs, _ = env.reset(seed=0)
    x, y, d, _ = (int(v) for v in obs["agent"])
    at_a = worldgraph.replay_route(env, graph.route_from_pose(x, y, d, a))
    at_b = worldgraph.replay_route(env, graph.route(a, b, facing=at_a.dir))
    assert (at_b.x, at_b.y) == graph.nodes[b]
    door_key = worldgraph.load_discover_run(run, task="doorkey")
    assert door_key.task == "doorkey" and door_key.layout_name == "small-doorkey"


def test_route_actions_are_a_list_of_ints_and_a_route_is_a_sequence_value(discover_run: pathlib.Path) -> None:
    import copy
    import pickle

    graph = worldgraph.load_discover_run(discover_run)
    a, b = farthest_pair(graph)
    route = graph.route(a, b)
    assert type(route.actions) is list and all(type(v) is int for v in route.actions)
    assert json.loads(json.dumps(route.actions)) == route.actions
    assert np.array(route.actions).shape == (len(route),)
    assert list(route) == route.actions  # iterating a route gives its actions
    assert route == graph.route(a, b) and hash(route) == hash(graph.route(a, b))
    assert route != graph.route(b, a) and route != route.actions
    assert pickle.loads(pickle.dumps(route)) == route and copy.deepcopy(route) == route
    again = worldgraph.Route(route.start, route.actions, route.cells, route.nodes)
    assert again == route
    with pytest.raises(ValueError, match=r"actions and cells must have the same length"):
        worldgraph.Route(route.start, route.actions, route.cells[:-1], route.nodes)
    with pytest.raises(ValueError, match=r"actions\[0\] must be an int from 0 to 5"):
        worldgraph.Route(route.start, [9], [route.cells[0]], route.nodes)


def test_a_world_graph_pickles_copies_and_round_trips_through_json(discover_run: pathlib.Path) -> None:
    import copy
    import pickle

    graph = worldgraph.load_discover_run(discover_run)
    for other in (pickle.loads(pickle.dumps(graph)), copy.deepcopy(graph), worldgraph.WorldGraph.from_json(graph.to_json())):
        assert other.nodes == graph.nodes and other.edges == graph.edges and other.task == graph.task
        assert other.route(0, 1) == graph.route(0, 1)
    with pytest.raises(worldgraph.PlanError):
        worldgraph.WorldGraph.from_json('{"format": "something else"}')


@pytest.mark.parametrize("facing", [4, 5, -1])
def test_a_facing_out_of_range_is_a_value_error(discover_run: pathlib.Path, facing: int) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    with pytest.raises(ValueError, match=rf"facing must be an int from 0 to 3, got {facing}"):
        graph.route(0, 1, facing=facing)
    x, y = graph.nodes[1]
    with pytest.raises(ValueError, match=rf"dir must be an int from 0 to 3, got {facing}"):
        graph.route_from_pose(x, y, facing, 0)


def test_node_and_cell_arguments_out_of_range_are_named(discover_run: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    assert graph.node_at(-1, 0) is None and graph.node_at(2**70, 0) is None
    with pytest.raises(worldgraph.PlanError, match=r"unknown node 1180591620717411303424"):
        graph.route(2**70, 0)
    with pytest.raises(ValueError, match=r"x must be an int from 0 to 12, got -1"):
        graph.route_from_pose(-1, 11, 0, 0)
    with pytest.raises(ValueError, match=r"carrying must be an int from 0 to 255, got -1"):
        graph.route_from_pose(1, 11, 0, 0, carrying=-1)


def test_route_from_pose_takes_the_observation_grid_as_it_comes(discover_run: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    env = gym.make("worldgraph/MultiGoal-Small-v0")
    obs, _ = env.reset(seed=0)
    x, y, d, c = obs["agent"]  # NumPy uint8 scalars, as they come
    target = farthest_pair(graph)[1]
    plain = graph.route_from_pose(x, y, d, target)
    assert obs["grid"].shape == (13, 13)
    for grid in (obs["grid"], obs["grid"].reshape(-1), obs["grid"].tolist(), obs["grid"].reshape(-1).tolist(), obs["grid"].astype(np.int64)):
        assert graph.route_from_pose(x, y, d, target, grid=grid, carrying=c) == plain
        assert graph.route(0, target, grid=grid) == graph.route(0, target)
    with pytest.raises(ValueError, match=r"grid must have shape \(13, 13\) or \(169,\), got \(4, 4\)"):
        graph.route_from_pose(x, y, d, target, grid=np.zeros((4, 4), np.uint8))
    bad = obs["grid"].copy()
    bad[3, 2] = 9
    with pytest.raises(ValueError, match=r"grid\[3, 2\] is 9: cell codes are 0 to 8"):
        graph.route_from_pose(x, y, d, target, grid=bad)
    with pytest.raises(TypeError, match=r"grid must be an integer array"):
        graph.route_from_pose(x, y, d, target, grid=obs["grid"].astype(np.float32))
    with pytest.raises(ValueError, match=r"grid must be an integer array of shape \(13, 13\): setting an array element"):
        graph.route_from_pose(x, y, d, target, grid=[[0, 1], [0]])
    # The walls are the graph's: a grid of another maze is refused, not half used.
    other = obs["grid"].copy()
    other[6, 3] = worldgraph.OBJECTS["wall"]
    with pytest.raises(ValueError, match=r"grid\[6, 3\] is a wall where the graph's layout has none"):
        graph.route_from_pose(x, y, d, target, grid=other)


def test_build_refuses_nodes_it_cannot_keep_instead_of_dropping_them() -> None:
    with pytest.raises(worldgraph.PlanError, match=r"cell \(0, 0\) holds wall"):
        worldgraph.WorldGraph.build([(1, 1), (0, 0), (3, 3)], maze="small")
    with pytest.raises(worldgraph.PlanError, match=r"cell \(1, 1\) is listed twice"):
        worldgraph.WorldGraph.build([(1, 1), (3, 3), (1, 1)], maze="small")
    sealed = "#########\n#>..#...#\n#..E#...#\n#########\n"
    with pytest.raises(worldgraph.PlanError, match=r"cell \(5, 1\) holds a cell unreachable from the agent's start"):
        worldgraph.WorldGraph.build([(1, 1), (5, 1)], layout=sealed)
    with pytest.raises(worldgraph.PlanError, match=r"cell \(9, 2\) holds key 'K'"):
        worldgraph.WorldGraph.build([(1, 11), (9, 2)], task="doorkey", maze="small")
    with pytest.raises(worldgraph.PlanError, match=r"cell \(-1, 3\) is outside the 13x13 grid"):
        worldgraph.WorldGraph.build([(1, 1), (-1, 3)], maze="small")
    with pytest.raises(ValueError, match=r"nodes\[1\] must be an \(x, y\) pair of ints, got \(1, 1, 0\)"):
        worldgraph.WorldGraph.build([(3, 3), (1, 1, 0)], maze="small")
    # Valid nodes keep the ids they were given.
    cells = [(3, 9), (1, 1), (11, 11), (5, 5)]
    assert worldgraph.WorldGraph.build(cells, maze="small").nodes == cells
    assert worldgraph.WorldGraph.build(np.array(cells), maze="small").nodes == cells
    # The cells a node may occupy are listed, for filtering beforehand.
    free = set(worldgraph.standable_cells(maze="small", task="doorkey"))
    assert (9, 6) not in free and (9, 2) not in free  # the walled-up passage, the key
    assert {(1, 11), (8, 9), (6, 9)} <= free  # behind the door, and the door itself (doors are passable)


def test_replay_route_refuses_an_env_that_is_not_at_the_route_start(discover_run: pathlib.Path) -> None:
    graph = worldgraph.load_discover_run(discover_run)
    env = gym.make("worldgraph/MultiGoal-Small-v0", balls=0)
    with pytest.raises(gym.error.ResetNeeded):
        worldgraph.replay_route(env, graph.route(0, 1))
    obs, _ = env.reset(seed=0)
    route = graph.route(0, 1)
    with pytest.raises(ValueError, match=r"the agent is at \(1, 11, 0\) but the route starts at"):
        worldgraph.replay_route(env, route)
    assert env.unwrapped.simulator.agent[0].tolist() == obs["agent"].tolist()  # nothing stepped
