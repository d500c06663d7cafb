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

Standard library only:

    for s in $(seq 100 150); do
      worldgraph evaluate RUN --seeds $s..$((s+1)) --trace traces/$s.json
    done
    python3 scripts/tour_overhead.py sim/mazes/small.txt traces/*.json
"""

import argparse
import itertools
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sparse_oracle import STEP_PENALTY, Maze  # noqa: E402

BALL = 2  # sim::Object::Ball


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("layout", help="the episodes' layout file (sim/mazes/*.txt)")
    ap.add_argument("traces", nargs="+", help="episode traces (JSON)")
    ap.add_argument("--balls", type=int, default=5, help="balls spawned an episode")
    a = ap.parse_args()
    maze = Maze(a.layout)
    xy = lambda c: (c % maze.width, c // maze.width)  # noqa: E731

    def score(k, steps):
        return k / a.balls - STEP_PENALTY * steps

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


if __name__ == "__main__":
    main()
