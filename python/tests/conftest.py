"""Shared fixtures of the Python package's tests (run by `make test`)."""

from __future__ import annotations

import json
import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def reference_binary() -> pathlib.Path:
    """The Rust reference of the differential test (sim/examples/
    reference_rollout.rs). `make test` builds it before pytest and sets
    WORLDGRAPH_REFERENCE, so there a missing binary fails; a bare `pytest`
    skips the differential test when it was never built."""
    env = os.environ.get("WORLDGRAPH_REFERENCE")
    path = pathlib.Path(env) if env else REPO / "target" / "release" / "examples" / "reference_rollout"
    if not path.exists():
        if env:
            pytest.fail(f"WORLDGRAPH_REFERENCE={env} does not exist")
        pytest.skip("build it first: cargo build --release -p sim --example reference_rollout")
    return path


@pytest.fixture(scope="session")
def discover_run(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """A directory shaped like a `worldgraph discover --maze small` run
    (graph.json, pivotal.json): the pivotal states the committed summary
    results/small/discover/seed-0.json reports, with the graph the planner
    builds over them (discovering anew needs libtorch and minutes)."""
    import worldgraph

    summary = json.loads((REPO / "results" / "small" / "discover" / "seed-0.json").read_text())
    cells = [tuple(c) for c in summary["summary"]["pivotal_cells"]]
    graph = worldgraph.WorldGraph.build(cells, task="multigoal", maze="small", seed=0)
    run = tmp_path_factory.mktemp("discover-small")
    graph.save(run / "graph.json")
    (run / "pivotal.json").write_text(json.dumps([list(c) for c in cells]))
    return run
