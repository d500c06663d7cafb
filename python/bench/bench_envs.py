#!/usr/bin/env python3
"""env-steps/s from Python: worldgraph's vector env against Gymnasium's
SyncVectorEnv over MiniGrid's own Python environment, in the same run.

    make bench-python                      # installs minigrid into .venv, then runs this
    .venv/bin/python python/bench/bench_envs.py --seconds 3 --envs 1 64 1024 --json

worldgraph: ``gym.make_vec("worldgraph/MultiGoal-Medium-v0", num_envs=N)``
(the batch's default threads: one per 256 environments, at most the
cores), the native ``Simulator.step`` underneath it (no Gymnasium layer),
and the same on one thread. MiniGrid:
``gym.make_vec("MiniGrid-FourRooms-v0", num_envs=N, vectorization_mode="sync")``
(a 19×19 four-room maze; MiniGrid's own rules in Python), skipped with a
note when ``minigrid`` is not importable. Actions are uniform random,
drawn before timing. Each figure is the best of ``--repeats`` windows of
``--seconds``; on a loaded machine they move, so compare figures of one run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import gymnasium as gym
import numpy as np

import worldgraph


def timed(step, actions: list[np.ndarray], n: int, seconds: float, repeats: int) -> float:
    """Best env-steps/s over `repeats` windows of about `seconds`."""
    best = 0.0
    for _ in range(repeats):
        steps, k = 0, 0
        start = time.perf_counter()
        deadline = start + seconds
        while True:
            for _ in range(8):
                step(actions[k % len(actions)])
                k += 1
            steps += 8 * n
            now = time.perf_counter()
            if now >= deadline:
                break
        best = max(best, steps / (now - start))
    return best


def actions_for(space_n: int, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    return [rng.integers(0, space_n, n, dtype=np.int64) for _ in range(64)]


def bench_worldgraph(n: int, seconds: float, repeats: int, rng: np.random.Generator) -> dict[str, float]:
    envs = gym.make_vec("worldgraph/MultiGoal-Medium-v0", num_envs=n)
    envs.reset(seed=0)
    acts = actions_for(envs.unwrapped.single_action_space.n, n, rng)
    vec = timed(envs.step, acts, n, seconds, repeats)
    sim = envs.unwrapped.simulator
    native = timed(sim.step, acts, n, seconds, repeats)
    threads = sim.threads
    envs.close()
    one = worldgraph.Simulator("multigoal", maze="medium", num_envs=n, seed=0, threads=1)
    native_1 = timed(one.step, acts, n, seconds, repeats)
    one.close()
    return {"vector_env": vec, "native_step": native, "native_step_1_thread": native_1, "threads": threads}


def bench_minigrid(n: int, seconds: float, repeats: int, rng: np.random.Generator) -> float | None:
    try:
        import minigrid  # noqa: F401  (registers the MiniGrid ids)
    except ImportError:
        return None
    envs = gym.make_vec("MiniGrid-FourRooms-v0", num_envs=n, vectorization_mode="sync")
    envs.reset(seed=0)
    acts = [rng.integers(0, 3, n, dtype=np.int64) for _ in range(64)]
    # MiniGrid steps ~10^4 env-steps/s: shorter windows would still hold many steps.
    rate = timed(envs.step, acts, n, seconds, repeats)
    envs.close()
    return rate


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--envs", type=int, nargs="+", default=[1, 64, 1024])
    ap.add_argument("--seconds", type=float, default=2.0, help="length of one timing window")
    ap.add_argument("--repeats", type=int, default=3, help="windows per figure (the best is kept)")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    rows = []
    for n in args.envs:
        wg = bench_worldgraph(n, args.seconds, args.repeats, rng)
        mg = bench_minigrid(n, args.seconds, args.repeats, rng)
        rows.append({"envs": n, **wg, "minigrid_sync": mg})
    load = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"cores": os.cpu_count(), "load_1min": load, "python": platform.python_version(), "rows": rows}))
        return 0
    print(f"env-steps/s, {os.cpu_count()} cores, 1-min load {load:.2f} at the end, Python {platform.python_version()}")
    print(
        f"{'envs':>6} {'threads':>7} {'worldgraph VectorEnv':>21} {'native Simulator.step':>22} "
        f"{'native, 1 thread':>17} {'MiniGrid SyncVectorEnv':>23} {'ratio':>8}"
    )
    for r in rows:
        mg = r["minigrid_sync"]
        mg_s = f"{mg:>23,.0f}" if mg is not None else f"{'(not installed)':>23}"
        ratio = f"{r['vector_env'] / mg:>7,.0f}x" if mg else f"{'-':>8}"
        print(
            f"{r['envs']:>6} {r['threads']:>7} {r['vector_env']:>21,.0f} {r['native_step']:>22,.0f} "
            f"{r['native_step_1_thread']:>17,.0f} {mg_s} {ratio}"
        )
    if rows and rows[0]["minigrid_sync"] is None:
        print("minigrid is not importable: the MiniGrid column was skipped (make bench-python installs it)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
