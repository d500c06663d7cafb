#!/usr/bin/env python3
"""The best MultiGoal-Sparse score a maze allows: an oracle that sees the
balls and plans.

For each random spawn of the balls (uniform over the free floor cells other
than the agent's start, as the simulator spawns them), the oracle tries every
subset and order of the balls followed by the exit, each leg a shortest path
in the simulator's moves (`left`, `right`, `forward`, one step each; the exit
ends the episode, so no leg crosses it), and keeps the best score
`balls / spawned - 0.01 * steps`. A ball a route crosses on the way is
taken by the order that lists it there, at the same length, so the search is
exact; `python/tests/test_sparse_oracle.py` checks it against a search over
states and plays its routes in the simulator.

Standard library only:

    python3 scripts/sparse_oracle.py sim/mazes/small.txt 200
"""

import argparse
import collections
import itertools
import random

STEP_PENALTY = 0.01
# east, south, west, north: the simulator's directions, `>` faces east.
DIRS = [(1, 0), (0, 1), (-1, 0), (0, -1)]
FACING = {">": 0, "v": 1, "<": 2, "^": 3}


class Maze:
    """A layout file's floor, its start and its exit, with shortest paths in
    the simulator's moves (states `(x, y, dir)`; the exit ends the episode,
    so no path crosses it)."""

    def __init__(self, path):
        rows = [r for r in open(path).read().split("\n") if r]
        self.width = len(rows[0])
        self.cells = {(x, y): ch for y, r in enumerate(rows) for x, ch in enumerate(r)}
        self.start = next((c, FACING[ch]) for c, ch in self.cells.items() if ch in FACING)
        self.exit_cell = next(c for c, ch in self.cells.items() if ch == "E")
        self.free = [c for c, ch in self.cells.items() if ch in "." or ch in FACING]
        # Where the simulator spawns balls: the floor other than the start.
        self.spawnable = [c for c in self.free if c != self.start[0]]
        self.s0 = (self.start[0][0], self.start[0][1], self.start[1])
        self._cache = {}
        self._floor_cache = {}

    def xy(self, c):
        """The `(x, y)` of cell index `c` (row-major, as traces name cells)."""
        return (c % self.width, c // self.width)

    def floor_dist(self, src):
        """Moves on the floor (turns not counted, the exit passable) from
        cell index `src` to every reachable cell index."""
        if src not in self._floor_cache:
            d = {src: 0}
            q = collections.deque([src])
            while q:
                u = q.popleft()
                for v in (u + 1, u - 1, u + self.width, u - self.width):
                    if self.cells.get(self.xy(v), "#") != "#" and v not in d:
                        d[v] = d[u] + 1
                        q.append(v)
            self._floor_cache[src] = d
        return self._floor_cache[src]

    def dist_from(self, s):
        """Steps from state `s = (x, y, dir)` to every reachable state."""
        if s not in self._cache:
            dist = {s: 0}
            q = collections.deque([s])
            while q:
                x, y, d = cur = q.popleft()
                nxt = [(x, y, (d + 1) % 4), (x, y, (d + 3) % 4)]
                fx, fy = x + DIRS[d][0], y + DIRS[d][1]
                if self.cells.get((fx, fy), "#") != "#" and (fx, fy) != self.exit_cell:
                    nxt.append((fx, fy, d))
                for n in nxt:
                    if n not in dist:
                        dist[n] = dist[cur] + 1
                        q.append(n)
            self._cache[s] = dist
        return self._cache[s]

    def to_exit(self, s):
        """Steps from state `s` onto the exit."""
        d = self.dist_from(s)
        best = float("inf")
        for k, (dx, dy) in enumerate(DIRS):
            before = (self.exit_cell[0] - dx, self.exit_cell[1] - dy, k)
            if before in d:
                best = min(best, d[before] + 1)
        return best

    def through(self, frontier, cell):
        """From `frontier` (`{state: steps}`), the fewest steps to stand on
        `cell`, by the direction faced there."""
        nf = {}
        for s, t in frontier.items():
            d = self.dist_from(s)
            for k in range(4):
                st = (cell[0], cell[1], k)
                if st in d and nf.get(st, float("inf")) > t + d[st]:
                    nf[st] = t + d[st]
        return nf

    def tour(self, cells):
        """The fewest steps from the start through `cells` in this order,
        then onto the exit."""
        frontier = {self.s0: 0}
        for c in cells:
            frontier = self.through(frontier, c)
        return min(t + self.to_exit(s) for s, t in frontier.items())


def best_routes(maze, balls, objective):
    """The oracle on one spawn: every subset and order of `balls` (cells),
    each followed by the exit. Returns `(best, by_count)`, each route an
    `(objective, balls taken, steps)`: `best` maximises `objective(k, steps)`,
    `by_count[k]` is the best route taking exactly `k` balls (None if none can)."""
    s0, to_exit = maze.s0, maze.to_exit
    best = (objective(0, to_exit(s0)), 0, to_exit(s0))
    # `best` stays the first best found, so ties keep the oracle's figures as they were.
    by_count = [best] + [None] * len(balls)
    for order in itertools.permutations(range(len(balls))):
        frontier = {s0: 0}
        for i, b in enumerate(order):
            frontier = maze.through(frontier, balls[b])
            steps = min(t + to_exit(s) for s, t in frontier.items())
            value = objective(i + 1, steps)
            if value > best[0]:
                best = (value, i + 1, steps)
            if by_count[i + 1] is None or value > by_count[i + 1][0]:
                by_count[i + 1] = (value, i + 1, steps)
    return best, by_count


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("layout", help="a layout file (sim/mazes/*.txt)")
    ap.add_argument("spawns", type=int, nargs="?", default=200, help="random spawns averaged")
    ap.add_argument("--balls", type=int, default=5, help="balls per spawn")
    ap.add_argument("--seed", type=int, default=0, help="seed of the spawns")
    ap.add_argument(
        "--gamma",
        type=float,
        default=1.0,
        help="pick the route that maximises the return discounted by gamma per step "
        "(the learners' objective; 0.99 by default there) and report its undiscounted score",
    )
    ap.add_argument(
        "--by-balls",
        action="store_true",
        help="also print, for each k, the mean best score of a route that takes at most k balls "
        "(what each further ball is worth to a planner on this layout)",
    )
    a = ap.parse_args()
    maze = Maze(a.layout)
    s0, to_exit = maze.s0, maze.to_exit

    def objective(k, steps):
        """What the oracle maximises: the score at `gamma = 1`, else the
        discounted return of `steps` step penalties then `k / balls` at the exit."""
        if a.gamma == 1.0:
            return k / a.balls - STEP_PENALTY * steps
        g = a.gamma
        return a.gamma**steps * k / a.balls - STEP_PENALTY * (1 - g**steps) / (1 - g)

    rng = random.Random(a.seed)
    total = balls_total = steps_total = 0.0
    # best_upto[k]: summed over spawns, the score of the best route taking at most k balls.
    best_upto = [0.0] * (a.balls + 1)
    for _ in range(a.spawns):
        balls = rng.sample(maze.spawnable, a.balls)
        best, by_count = best_routes(maze, balls, objective)
        upto = by_count[0]
        for k, route in enumerate(by_count):
            if route[0] > upto[0]:
                upto = route
            best_upto[k] += upto[1] / a.balls - STEP_PENALTY * upto[2]
        total += best[1] / a.balls - STEP_PENALTY * best[2]
        balls_total += best[1]
        steps_total += best[2]
    n = a.spawns
    print(
        f"oracle (gamma {a.gamma}): mean score {total / n:.3f}, balls {balls_total / n:.2f}, "
        f"steps {steps_total / n:.1f} over {n} spawns of {a.balls} balls"
    )
    direct = to_exit(s0)
    print(f"exit at once (no ball): {direct} steps, score {-STEP_PENALTY * direct:.3f}")
    if a.by_balls:
        for k, v in enumerate(best_upto):
            print(f"at most {k} ball(s): mean score {v / n:.3f}")


if __name__ == "__main__":
    main()
