#!/usr/bin/env python3
"""Which way the Wide-then-Narrow Worker walks to its narrow goal: straight,
or through the wide goal.

Reads the test episodes a `worldgraph train` run records
(`<run>/test_episode.json`: the cell after every step, whether a traversal
took it, and the Manager's decisions `[step, g_w, g_n]`). For every interval
that the Worker walked alone (no traversal step) and that reached `g_n`, it
compares the cells the agent moved with two shortest ways on the layout's
floor (moves between cells, turns not counted): straight to `g_n`, and to
`g_w` first, then to `g_n`. Intervals where the two are equal say nothing and
are skipped. The Worker is paid for `g_w` on arrival and for `g_n`
(section 4.2), so a Worker that walks through `g_w` where it is out of the way
is following that reward, not the task's.

Standard library only:

    python3 scripts/worker_detours.py sim/mazes/small.txt results/<set>/runs/<grid>/small/*/*/seed-*
"""

import argparse
import collections
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sparse_oracle import Maze  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("layout", help="the runs' layout file (sim/mazes/*.txt); '#' is wall")
    ap.add_argument("runs", nargs="+", help="run directories holding test_episode.json")
    a = ap.parse_args()
    dist = Maze(a.layout).floor_dist

    kinds = collections.Counter()
    print(f"{'run':60} {'moved':>5} {'straight':>8} {'via g_w':>7}  way")
    for run in a.runs:
        path = os.path.join(run, "test_episode.json")
        if not os.path.exists(path):
            continue
        ep = json.load(open(path))
        cells, traversed, goals = ep["cells"], ep["traversed"], ep["goals"]
        for i, (start, wide, narrow) in enumerate(goals):
            end = goals[i + 1][0] if i + 1 < len(goals) else len(cells) - 1
            if any(traversed[start:end]) or cells[end] != narrow:
                continue
            moved = sum(1 for k in range(start + 1, end + 1) if cells[k] != cells[k - 1])
            straight = dist(cells[start])[narrow]
            via = dist(cells[start])[wide] + dist(wide)[narrow]
            if straight == via:
                continue
            way = "via g_w" if moved == via else "straight" if moved == straight else "other"
            kinds[way] += 1
            print(f"{run[-60:]:60} {moved:5} {straight:8} {via:7}  {way}")
    total = sum(kinds.values())
    print(
        f"\n{total} intervals where the ways differ: "
        + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))
    )


if __name__ == "__main__":
    main()
