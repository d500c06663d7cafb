"""Shared fixtures of the Python package's tests (run by `make test`)."""

from __future__ import annotations

import json
import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


def rust_binary(variable: str, default: pathlib.Path, build: str) -> pathlib.Path:
    """A Rust program a test runs: `$variable`, else `default`. Missing, it
    fails the test under `make test` (WORLDGRAPH_REQUIRE_RUST=1), which
    builds it first, and skips it under a bare `pytest`."""
    path = pathlib.Path(os.environ.get(variable) or default)
    if not path.exists():
        if os.environ.get("WORLDGRAPH_REQUIRE_RUST"):
            pytest.fail(f"{path} does not exist ({variable})")
        pytest.skip(f"{path} does not exist; build it first: {build}")
    return path


@pytest.fixture(scope="session")
def reference_binary() -> pathlib.Path:
    """The Rust reference of the differential test (sim/examples/reference_rollout.rs)."""
    return rust_binary(
        "WORLDGRAPH_REFERENCE",
        REPO / "target" / "release" / "examples" / "reference_rollout",
        "cargo build --release -p sim --example reference_rollout",
    )


@pytest.fixture(scope="session")
def worldgraph_binary() -> pathlib.Path:
    """The `worldgraph` command line (needs libtorch: `make test` builds it)."""
    return rust_binary("WORLDGRAPH_BIN", REPO / "target" / "release" / "worldgraph", "make test")


@pytest.fixture(scope="session")
def discover_run(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A directory shaped like a `worldgraph discover --maze small` run
    (graph.json, pivotal.json): the pivotal states the committed summary
    results/archive/105k/small/discover/seed-0.json reports, with the graph the planner
    builds over them (discovering anew needs libtorch and minutes)."""
    import worldgraph

    summary = json.loads((REPO / "results" / "archive" / "105k" / "small" / "discover" / "seed-0.json").read_text())
    cells = [tuple(c) for c in summary["summary"]["pivotal_cells"]]
    graph = worldgraph.WorldGraph.build(cells, task="multigoal", maze="small", seed=0)
    run = tmp_path_factory.mktemp("discover-small")
    graph.save(run / "graph.json")
    (run / "pivotal.json").write_text(json.dumps([list(c) for c in cells]))
    return run


@pytest.fixture(scope="session")
def real_run(tmp_path_factory: pytest.TempPathFactory):
    """`real_run(maze, seed)`: a directory shaped like a `worldgraph
    discover` run of the paper-real grid (results/paper-real/{maze}/discover/
    seed-{seed}.json): its pivotal states, with the MultiGoal graph the
    planner builds over them."""
    import worldgraph

    made: dict[tuple[str, int], pathlib.Path] = {}

    def make(maze: str, seed: int) -> pathlib.Path:
        if (maze, seed) not in made:
            report = REPO / "results" / "paper-real" / maze / "discover" / f"seed-{seed}.json"
            cells = [tuple(c) for c in json.loads(report.read_text())["summary"]["pivotal_cells"]]
            run = tmp_path_factory.mktemp(f"discover-{maze}-{seed}")
            worldgraph.WorldGraph.build(cells, task="multigoal", maze=maze, seed=seed).save(run / "graph.json")
            (run / "pivotal.json").write_text(json.dumps([list(c) for c in cells]))
            made[maze, seed] = run
        return made[maze, seed]

    return make
