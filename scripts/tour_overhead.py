#!/usr/bin/env python3
"""Where a MultiGoal agent's episode loses steps against the shortest tour
through the same balls: the way it walks, the order of the balls, or the
balls it leaves.

Reads episode traces (`test_episode.json` of a run, or the files
`worldgraph evaluate --trace` writes): the cell after every step and the grid
at the start. For each episode it finds the balls collected, in the order the
agent stepped on them, and compares, in the simulator's moves (turns count):

- `steps`: the episode's length;
- `same order`: the shortest walk from the start through those balls in that
  order, then onto the exit;
- `best order`: the shortest through the same balls in any order;
- the oracle's best score over every subset and order of the episode's balls
  (`scripts/sparse_oracle.py`'s search on this spawn).

`steps - same order` is lost on the way between goals (the Worker's walk, its
turns, traversal routes), `same order - best order` to the order the Manager
names the balls in, and the oracle's score against the best order's to the
balls the agent leaves. Scores are MultiGoal-Sparse's: `balls / 5 - 0.01 a
step`.

Two more figures say where those losses sit:
- every Manager interval that named a ball as `g_n` and reached it, walked by
  the Worker or helped by a traversal: its steps against the shortest walk
  from where it began (the traces record no facing, so the agent is taken to
  face its last move: an estimate);
- the balls left, by how far they lie off the path walked (cells on the
  floor from the nearest cell the agent stood on).

Standard library only:

    for s in $(seq 100 150); do
      worldgraph evaluate RUN --seeds $s..$((s+1)) --trace traces/$s.json
    done
    python3 scripts/tour_overhead.py sim/mazes/small.txt traces/*.json
"""

import argparse
import collections
import itertools
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sparse_oracle import DIRS, STEP_PENALTY, Maze  # noqa: E402

BALL = 2  # sim::Object::Ball


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("layout", help="the episodes' layout file (sim/mazes/*.txt)")
    ap.add_argument("traces", nargs="+", help="episode traces (JSON)")
    ap.add_argument("--balls", type=int, default=5, help="balls spawned an episode")
    a = ap.parse_args()
    maze = Maze(a.layout)
    xy = maze.xy

    def score(k, steps):
        return k / a.balls - STEP_PENALTY * steps

    intervals = collections.defaultdict(lambda: [0, 0, 0])  # n, steps, shortest
    left_off = collections.Counter()
    rows = []
    for path in a.traces:
        ep = json.load(open(path))
        cells = ep["cells"]
        balls = [c for c, v in enumerate(ep["start_cells"]) if v == BALL]
        order = []
        for c in cells:
            if c in balls and c not in order:
                order.append(c)
        exited = xy(cells[-1]) == maze.exit_cell
        steps = len(cells) - 1
        same = maze.tour([xy(c) for c in order])
        best = min(maze.tour([xy(c) for c in p]) for p in itertools.permutations(order))
        oracle = max(
            score(k, maze.tour([xy(c) for c in p]))
            for k in range(len(balls) + 1)
            for p in itertools.permutations(balls, k)
        )
        rows.append((path, exited, len(order), steps, same, best, oracle))
        # The intervals that named a ball as g_n and reached it.
        facing = [maze.start[1]]
        for t in range(len(cells) - 1):
            u, v = cells[t], cells[t + 1]
            if u == v:
                facing.append(facing[-1])
            else:
                (x0, y0), (x1, y1) = xy(u), xy(v)
                facing.append(DIRS.index((x1 - x0, y1 - y0)))
        goals = ep.get("goals", [])
        for i, (start, _wide, narrow) in enumerate(goals):
            end = goals[i + 1][0] if i + 1 < len(goals) else len(cells) - 1
            if cells[end] != narrow or narrow not in balls:
                continue
            d = maze.dist_from((*xy(cells[start]), facing[start]))
            shortest = min(d.get((*xy(narrow), k), float("inf")) for k in range(4))
            kind = "with a traversal" if any(ep["traversed"][start:end]) else "walked"
            intervals[kind][0] += 1
            intervals[kind][1] += end - start
            intervals[kind][2] += shortest
        for b in balls:
            if b not in order:
                left_off[min(min(maze.floor_dist(b).get(c, 99) for c in set(cells)), 3)] += 1
        print(
            f"{os.path.basename(path):24} balls {len(order)} steps {steps:4} same order {same:3} "
            f"best order {best:3}  score {score(len(order), steps):6.3f} oracle {oracle:6.3f}"
            + ("" if exited else "  (no exit)")
        )
    ran = [r for r in rows if r[1]]
    if not ran:
        print("no episode reached the exit")
        return
    n = len(ran)
    mean = lambda i: sum(r[i] for r in ran) / n  # noqa: E731
    k, steps, same, best, oracle = mean(2), mean(3), mean(4), mean(5), mean(6)
    print(
        f"\n{n} of {len(rows)} episodes exit. Means over them: balls {k:.2f}, steps {steps:.1f}, "
        f"same order {same:.1f}, best order {best:.1f}"
    )
    print(
        f"score {score(k, steps):.3f}; lost on the way {STEP_PENALTY * (steps - same):.3f}, "
        f"to the order {STEP_PENALTY * (same - best):.3f}, "
        f"to the balls left {oracle - score(k, best):.3f}; oracle {oracle:.3f}"
    )
    for kind, (count, taken, shortest) in sorted(intervals.items()):
        print(
            f"intervals to a ball, {kind}: {count}, {(taken - shortest) / count:.1f} steps "
            "a ball more than the shortest walk (estimate)"
        )
    left = sum(left_off.values())
    if left:
        near = left_off[1] + left_off[2]
        print(
            f"balls left: {left / len(rows):.2f} an episode, {100 * near / left:.0f} % of them "
            "one or two cells off the path walked"
        )


if __name__ == "__main__":
    main()
