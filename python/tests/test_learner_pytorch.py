"""The PyTorch reference of `worldgraph bench learner`
(benches/learner_pytorch.py): its input planes are the Rust learner's
(`learner/src/a2c/input.rs`), and each agent trains and reports. Skipped
without torch (`make bench-learner-python` installs it)."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from conftest import REPO

torch = pytest.importorskip("torch")


def load_script():
    spec = importlib.util.spec_from_file_location("learner_pytorch", REPO / "benches" / "learner_pytorch.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def naive_planes(grid, agent, goals, channels):
    """`encode_obs` written out cell by cell."""
    n, h, w = grid.shape
    x = np.zeros((n, channels, h, w), np.float32)
    for i in range(n):
        for y in range(h):
            for c in range(w):
                x[i, min(grid[i, y, c], 8), y, c] = 1.0
        ax, ay, d, carrying = agent[i]
        x[i, 9 + (d & 3), ay, ax] = 1.0
        if carrying == 3:
            x[i, 13] = 1.0
        for k, g in enumerate(goals[i] if goals is not None else []):
            if g >= 0:
                x[i, 14 + k, g // w, g % w] = 1.0
    return x


@pytest.mark.parametrize("channels_last", [False, True])
def test_planes_are_the_rust_learners_one_hot_input(channels_last: bool) -> None:
    m = load_script()
    rng = np.random.default_rng(1)
    n, h, w = 5, 7, 9
    grid = rng.integers(0, 9, size=(n, h, w), dtype=np.uint8)
    agent = np.stack(
        [rng.integers(0, w, n), rng.integers(0, h, n), rng.integers(0, 4, n), [3, 255, 3, 2, 255]], 1
    ).astype(np.uint8)
    goals = np.array([[3, 10], [-1, 0], [62, -1], [-1, -1], [5, 5]], np.int64)
    planes = m.Planes(h, w, 2, channels_last)
    x = planes.encode(grid, agent, goals)
    assert x.shape == (n, 16, h, w)
    assert x.is_contiguous(memory_format=torch.channels_last) == channels_last
    np.testing.assert_array_equal(x.numpy(), naive_planes(grid, agent, goals, 16))
    # Into a reused buffer: stale ones are cleared.
    out = torch.ones(n, planes.c * h * w)
    np.testing.assert_array_equal(planes.encode(grid, agent, goals, out=out).numpy(), x.numpy())


@pytest.mark.parametrize("agent", ["a2c", "gcp", "wn"])
def test_each_agent_trains_and_prints_one_json_line(agent: str, capsys: pytest.CaptureFixture[str]) -> None:
    m = load_script()
    args = ["--agent", agent, "--maze", "small", "--envs", "4", "--rollout", "6", "--threads", "1", "--seconds", "0.6"]
    assert m.main(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    r = json.loads(lines[0])
    assert r["env_steps_per_sec"] > 0 and r["iterations"] >= 1 and r["threads"] == 1
    assert r["torch_version"] == torch.__version__
    assert set(r["variants"]) == {f"{p}/{l}" for p in ("per-step", "recompute") for l in ("nchw", "channels-last")}
    assert r["variant"] in r["variants"] and r["variant"] == f"{r['path']}/{r['layout']}"
    assert 0.0 < r["env_share"] < 1.0
    if agent == "wn":
        assert r["window_side"] % 2 == 1 and r["candidates"] == 24
        assert r["manager_decisions_per_env_step"] > 0
