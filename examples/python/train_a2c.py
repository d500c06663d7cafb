#!/usr/bin/env python3
"""A2C with PyTorch on worldgraph's vector environment (not run by CI).

    make python                                   # builds worldgraph into .venv
    .venv/bin/pip install torch                   # not part of make test
    .venv/bin/python examples/python/train_a2c.py --env worldgraph/MultiGoal-Small-v0 --steps 2000000

The observation arrays are the simulator's own buffers (zero copy):
``torch.from_numpy`` shares them, and the network reads them before the
next ``step`` rewrites them. The policy sees the grid one-hot (9 cell codes)
plus the agent's cell in one of 4 facing planes; n-step returns bootstrap
from the finished episode's final observation on truncation (same-step
auto-reset puts it in ``infos["final_obs"]``) and stop at termination.
Prints env steps, wall seconds, the mean return and balls of the last 100
finished episodes, and a random policy's mean return for comparison.
"""

from __future__ import annotations

import argparse
import collections
import time

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import worldgraph  # noqa: F401  (registers the ids)


def encode(grid: torch.Tensor, agent: torch.Tensor) -> torch.Tensor:
    """(N, H, W) cell codes and (N, 4) agents -> (N, 13, H, W) float planes."""
    n, h, w = grid.shape
    x = torch.zeros(n, 13, h, w)
    x.scatter_(1, grid.long().unsqueeze(1), 1.0)
    idx = torch.arange(n)
    x[idx, 9 + agent[:, 2].long(), agent[:, 1].long(), agent[:, 0].long()] = 1.0
    return x


class Net(nn.Module):
    def __init__(self, h: int, w: int, actions: int) -> None:
        super().__init__()
        # An MLP over the planes: on 2 busy cores a convolution made the
        # network, not the simulator, the whole cost of a step.
        self.body = nn.Sequential(
            nn.Flatten(), nn.Linear(13 * h * w, 256), nn.ReLU(), nn.Linear(256, 256), nn.ReLU()
        )
        self.pi = nn.Linear(256, actions)
        self.v = nn.Linear(256, 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        z = self.body(x)
        return self.pi(z), self.v(z).squeeze(-1)


def random_return(env_id: str, episodes: int = 200) -> float:
    envs = gym.make_vec(env_id, num_envs=64)
    envs.reset(seed=12345)
    rng, done = np.random.default_rng(0), []
    while len(done) < episodes:
        _, _, _, _, info = envs.step(rng.integers(0, envs.single_action_space.n, 64))
        if info:
            done += list(info["final_info"]["episode"]["r"][info["_final_info"]])
    return float(np.mean(done))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--env", default="worldgraph/MultiGoal-Small-v0")
    ap.add_argument("--envs", type=int, default=64)
    ap.add_argument("--nsteps", type=int, default=16)
    ap.add_argument("--steps", type=int, default=2_000_000, help="env steps")
    ap.add_argument("--lr", type=float, default=7e-4)
    ap.add_argument("--gamma", type=float, default=0.99)
    ap.add_argument("--entropy", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    envs = gym.make_vec(args.env, num_envs=args.envs)
    n, (h, w) = args.envs, envs.single_observation_space["grid"].shape
    net = Net(h, w, envs.single_action_space.n)
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    obs, _ = envs.reset(seed=args.seed)
    grid, agent = torch.from_numpy(obs["grid"]), torch.from_numpy(obs["agent"])  # shared, not copied
    returns, balls = collections.deque(maxlen=100), collections.deque(maxlen=100)
    start, steps, next_print = time.time(), 0, 0
    print(f"{args.env}: random policy's mean return {random_return(args.env):.2f}")
    while steps < args.steps:
        xs, acts, rews, conts, boot = [], [], [], [], []
        for _ in range(args.nsteps):
            x = encode(grid, agent)  # read before step() rewrites the buffers
            with torch.no_grad():
                logits, _ = net(x)
            a = torch.distributions.Categorical(logits=logits).sample()
            _, r, term, trunc, info = envs.step(a.numpy())
            # Truncated episodes bootstrap from their final observation.
            b = torch.zeros(n)
            if info:
                done = info["_final_obs"]
                for i in np.flatnonzero(done):
                    returns.append(float(info["final_info"]["episode"]["r"][i]))
                    balls.append(int(info["final_info"]["balls"][i]))
                tr = np.flatnonzero(trunc)
                if len(tr):
                    fo = info["final_obs"]
                    fg = torch.from_numpy(np.stack([fo[i]["grid"] for i in tr]))
                    fa = torch.from_numpy(np.stack([fo[i]["agent"] for i in tr]))
                    with torch.no_grad():
                        b[tr] = net(encode(fg, fa))[1]
            xs.append(x)
            acts.append(a)
            rews.append(torch.from_numpy(r.copy()) + args.gamma * b)
            conts.append(torch.from_numpy(~(term | trunc)).float())
            steps += n
        with torch.no_grad():
            ret = net(encode(grid, agent))[1]
        targets = []
        for r, c in zip(reversed(rews), reversed(conts)):
            ret = r + args.gamma * c * ret
            targets.append(ret)
        targets = torch.cat(targets[::-1])
        logits, v = net(torch.cat(xs))
        dist = torch.distributions.Categorical(logits=logits)
        adv = targets - v
        loss = (
            -(dist.log_prob(torch.cat(acts)) * adv.detach()).mean()
            + 0.5 * adv.pow(2).mean()
            - args.entropy * dist.entropy().mean()
        )
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(net.parameters(), 0.5)
        opt.step()
        if steps >= next_print:
            next_print += args.steps // 20
            mean_r = np.mean(returns) if returns else float("nan")
            mean_b = np.mean(balls) if balls else float("nan")
            print(f"{steps:>10,} env steps {time.time() - start:7.1f} s  return {mean_r:6.2f}  balls {mean_b:4.2f}")
    envs.close()


if __name__ == "__main__":
    main()
