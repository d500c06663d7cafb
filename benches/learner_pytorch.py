#!/usr/bin/env python3
"""The PyTorch reference of ``worldgraph bench learner`` (issue 26).

An independent PyTorch-Python implementation of the networks and the A2C
update of worldgraph's Rust learners (``learner/src/a2c``, ``gcp/``,
``hrl/``), trained on the project's own simulator through its Python
package (``worldgraph/MultiGoal-{Small,Medium,Large}-v0``, the same Rust
environments the Rust bench steps), so that ``bench learner`` can state its
env-steps/s as a ratio against PyTorch on the same threads. Prints one JSON
line.

What it implements, per agent (sizes of ``AgentConfig::default()`` and
``GcpConfig::default()``):

- the actor-critic of ``learner/src/a2c/net.rs``: dense one-hot planes
  ``[N, C, H, W]`` (``input.rs``: 9 object kinds, 4 agent facings, the
  carried key, then the goal planes) → 3×3 conv (16, stride 1, pad 1) →
  ReLU → 3×3 conv (32, stride 2, pad 1) → ReLU → flatten → linear (``--hidden``,
  128) → ReLU → LSTM cell (``--hidden``) → policy (3 actions) and value heads;
- the A2C update of ``a2c/mod.rs`` and ``a2c/rollout.rs``: GAE (λ 0.95),
  ``L = L_π + 0.5 L_V − 0.01 H``, Adam, global gradient-norm clip 0.5, the
  LSTM state carried across rollouts (truncated BPTT over the rollout) and
  zeroed where an episode (a goal episode) ends, steps cut by the step
  limit bootstrapped from ``V`` of their final state;
- ``a2c``: the baseline, no goal plane, the task's reward, γ 0.99, lr 7e-4,
  rollout 60;
- ``gcp``: ``π_g`` (one goal plane), γ 0.95, lr 1e-3, rollout 16; its goal
  reward 1 and step penalty −0.01; a goal episode ends on arrival, after
  24 steps (``goal_time_factor · goal_walk_len``) or with the environment's
  episode. Simplified: the goal is a random free cell, not the end of a
  random walk of 6 moves (the compute per env step is the same);
- ``wn``: the Wide-then-Narrow agent of ``hrl/``: the Worker (two goal
  planes, ``g_w`` until paid and ``g_n``; paid for reaching either, its goal
  episode and the Manager's interval end on reaching ``g_n``, after
  ``c = rollout / 3`` steps or with the episode) runs at every env step; the
  Manager (its own trunk without goal plane, a value head, ``π^ω`` a linear
  layer onto the candidates, ``π^n`` a two-layer net over ``[h ; s_w(g_w) ;
  onehot(g_w)]`` onto the ``N×N`` window, masked to free cells) runs at its
  decisions and is trained by its own A2C update over the decision queues
  (interval rewards summed, discount ``γ^k``, the interval under way carried
  to the next update with the core state before it). Candidates: random
  free cells, as many as ``WorldGraphInputs::random_for_bench`` has;
  window side: ``--window`` (the Rust bench passes its own), else the
  smallest odd side from 5 (7 beyond 25 columns) whose windows cover every
  free cell, as ``wide_narrow::covering_side``. Simplified: no world-graph
  traversal. The Rust bench's WN traverses; the Worker's network still runs
  at every env step there (its loss skips the traversal steps with weight
  0), so the compute per env step is the same, but traversal steps do not
  count towards the horizon ``c``, so its intervals are longer and its
  Manager decides less often. To match the Manager's work per env step, the
  Rust bench passes ``--horizon`` = 1 / its measured decisions per env step
  (the Worker steps after which an interval ends here); both sides report
  their decisions per env step.

The update is computed two ways, both ordinary PyTorch: ``per-step`` keeps
every step's autograd graph (acting with gradient) and back-propagates
through the whole rollout; ``recompute`` acts under ``torch.no_grad()``,
stores the encoded planes, and recomputes the encoder for all ``T·B``
observations in one batched pass before unrolling the LSTM cell over the
stored features (CleanRL's PPO-LSTM layout). Each runs with the planes and
convolutions in NCHW or in channels-last layout (the planes are written
straight in that layout). With ``--path best --layout best`` (the defaults)
the four variants are measured in alternating windows of the same run and
the fastest one's rate is reported (the median of its windows), so the
reference is the best of the idioms, not a chosen one. Adam is
``torch.optim.Adam(fused=True)``, the clip ``clip_grad_norm_(foreach=True)``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

try:
    import torch
    import torch.nn.functional as F
    from torch import nn
except ImportError:  # pragma: no cover - reported as JSON
    print(json.dumps({"error": "torch is not importable", "env_steps_per_sec": None}))
    sys.exit(3)

import gymnasium as gym

import worldgraph  # noqa: F401  (registers the environment ids)

#: Object kinds (``sim::object::NUM_OBJECTS``), then 4 facings and the key.
OBJECTS = 9
BASE_CHANNELS = OBJECTS + 5
KEY_CHANNEL = OBJECTS + 4
KEY_CODE = 3
WALL_CODE = 1
#: Floats per window cell of the Manager's local input (object kinds + agent).
WINDOW_CHANNELS = OBJECTS + 1
#: Wide-goal candidates of ``WorldGraphInputs::random_for_bench``.
BENCH_CANDIDATES = 24
MASKED_LOGIT = -1e9


class Planes:
    """Dense one-hot input planes of a batch (``learner/src/a2c/input.rs``'s
    ``encode_obs``), written with a few vectorised scatters; in
    channels-last layout the buffer is ``[N, H, W, C]`` viewed as NCHW."""

    def __init__(self, height: int, width: int, goal_planes: int, channels_last: bool) -> None:
        self.h, self.w, self.hw = height, width, height * width
        self.c = BASE_CHANNELS + goal_planes
        self.goal_planes = goal_planes
        self.channels_last = channels_last
        if channels_last:
            # Element (cell p, channel ch) at p·C + ch.
            self.cell_stride, self.chan_stride = self.c, 1
        else:
            self.cell_stride, self.chan_stride = 1, self.hw
        self.cells = torch.arange(self.hw) * self.cell_stride
        key = torch.arange(self.hw) * self.cell_stride + KEY_CHANNEL * self.chan_stride
        self.key_index = key

    def alloc(self, n: int) -> torch.Tensor:
        return torch.zeros(n, self.c * self.hw)

    def view(self, flat: torch.Tensor) -> torch.Tensor:
        n = flat.shape[0]
        if self.channels_last:
            return flat.view(n, self.h, self.w, self.c).permute(0, 3, 1, 2)
        return flat.view(n, self.c, self.h, self.w)

    def encode(self, grid: np.ndarray, agent: np.ndarray, goals: np.ndarray | None = None, out=None):
        """Planes of ``grid`` ``[N, H, W]`` and ``agent`` ``[N, 4]`` (uint8),
        goal cells ``goals`` ``[N, goal_planes]`` (−1: none) on their own
        planes; into ``out`` (``[N, C·H·W]``, zeroed here) when given."""
        n = grid.shape[0]
        flat = self.alloc(n) if out is None else out.zero_()
        codes = torch.from_numpy(grid).reshape(n, self.hw).to(torch.int64).clamp_(max=OBJECTS - 1)
        flat.scatter_(1, codes * self.chan_stride + self.cells, 1.0)
        a = torch.from_numpy(agent).to(torch.int64)
        rows = torch.arange(n)
        cell = a[:, 1] * self.w + a[:, 0]
        flat[rows, cell * self.cell_stride + (OBJECTS + (a[:, 2] & 3)) * self.chan_stride] = 1.0
        key = a[:, 3] == KEY_CODE
        if bool(key.any()):
            flat[key.nonzero().squeeze(1)[:, None], self.key_index[None, :]] = 1.0
        if goals is not None and self.goal_planes:
            g = torch.from_numpy(goals)
            for k in range(self.goal_planes):
                ok = g[:, k] >= 0
                r = rows[ok]
                flat[r, g[ok, k] * self.cell_stride + (BASE_CHANNELS + k) * self.chan_stride] = 1.0
        return self.view(flat)


class Trunk(nn.Module):
    """Encoder + LSTM cell (``net.rs``'s ``Trunk``)."""

    def __init__(self, cin: int, conv: tuple[int, int], hidden: int, height: int, width: int) -> None:
        super().__init__()
        c1, c2 = conv
        self.conv1 = nn.Conv2d(cin, c1, 3, stride=1, padding=1)
        self.conv2 = nn.Conv2d(c1, c2, 3, stride=2, padding=1)
        self.fc = nn.Linear(c2 * ((height + 1) // 2) * ((width + 1) // 2), hidden)
        self.core = nn.LSTMCell(hidden, hidden)
        self.hidden = hidden

    def features(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.conv2(F.relu(self.conv1(x))))
        return F.relu(self.fc(y.flatten(1)))

    def step(self, x: torch.Tensor, state):
        return self.core(self.features(x), state)

    def zeros(self, n: int):
        return (torch.zeros(n, self.hidden), torch.zeros(n, self.hidden))


class ActorCritic(nn.Module):
    """Trunk + policy and value heads (``net.rs``'s ``ActorCritic``)."""

    def __init__(self, cin, conv, hidden, actions, height, width) -> None:
        super().__init__()
        self.trunk = Trunk(cin, conv, hidden, height, width)
        self.policy = nn.Linear(hidden, actions)
        self.value = nn.Linear(hidden, 1)

    def heads(self, h):
        return self.policy(h), self.value(h).squeeze(-1)

    def step(self, x, state):
        h, c = self.trunk.step(x, state)
        logits, value = self.heads(h)
        return logits, value, (h, c)


def gae(rewards, values, discounts, bootstrap, lam):
    """``a2c::advantages`` over ``[K, B]`` numpy arrays: returns ``(Â, R)``."""
    k = rewards.shape[0]
    adv = np.zeros_like(rewards)
    next_value = bootstrap.astype(np.float32)
    next_adv = np.zeros_like(next_value)
    for t in range(k - 1, -1, -1):
        d = discounts[t]
        delta = rewards[t] + d * next_value - values[t]
        next_adv = delta + d * lam * next_adv
        adv[t] = next_adv
        next_value = values[t]
    return adv, adv + values


def a2c_loss(logits, values, actions, adv, ret, weights, value_coef, entropy_coef, extra=None):
    """``a2c::a2c_loss``: ``L_π + c_V L_V − c_H H`` over weighted entries;
    ``extra`` gives ``(log_prob, entropy)`` for heads other than one
    categorical over ``logits``."""
    w = torch.from_numpy(weights)
    denom = max(float(weights.sum()), 1.0)
    if extra is None:
        logp = F.log_softmax(logits, -1)
        log_prob = logp.gather(1, actions[:, None]).squeeze(1)
        entropy = -(logp.exp() * logp).sum(-1)
    else:
        log_prob, entropy = extra
    policy_loss = -(torch.from_numpy(adv) * log_prob * w).sum() / denom
    value_loss = 0.5 * ((torch.from_numpy(ret) - values).square() * w).sum() / denom
    ent = (entropy * w).sum() / denom
    return policy_loss + value_coef * value_loss - entropy_coef * ent


def make_optimizer(params, lr, fused):
    if fused:
        return torch.optim.Adam(params, lr=lr, fused=True)
    return torch.optim.Adam(params, lr=lr, foreach=True)


class Timer:
    """Seconds per phase."""

    def __init__(self) -> None:
        self.t = {"env": 0.0, "encode": 0.0, "act": 0.0, "update": 0.0, "manager": 0.0}
        self.last = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.t[phase] += now - self.last
        self.last = now

    def mark(self) -> None:
        """Restarts the lap without booking (the time goes to "other")."""
        self.last = time.perf_counter()


class EveryStep:
    """An every-step learner's rollout and update (``a2c/rollout.rs``) on
    ``net``: ``per-step`` keeps the graphs, ``recompute`` acts without them
    and recomputes the rollout in one batched pass."""

    def __init__(self, net, planes, n, steps, path, gamma, lam, lr, fused):
        self.net, self.planes, self.n, self.steps, self.path = net, planes, n, steps, path
        self.gamma, self.lam = gamma, lam
        self.params = list(net.parameters())
        self.opt = make_optimizer(self.params, lr, fused)
        self.state = net.trunk.zeros(n)
        self.buf = planes.alloc(steps * n) if path == "recompute" else None

    def start(self):
        self.state = (self.state[0].detach(), self.state[1].detach())
        self.init = self.state
        self.t = 0
        self.logits, self.values_g = [], []
        self.actions, self.values = [], []
        self.rewards = np.zeros((self.steps, self.n), np.float32)
        self.dones = np.zeros((self.steps, self.n), np.float32)
        self.weights = np.ones((self.steps, self.n), np.float32)

    def encode(self, grid, agent, goals):
        if self.path == "recompute":
            out = self.buf[self.t * self.n : (self.t + 1) * self.n]
            return self.planes.encode(grid, agent, goals, out=out)
        return self.planes.encode(grid, agent, goals)

    def act(self, x):
        """One step: returns the sampled actions (numpy) and the next core
        state (before any reset)."""
        if self.path == "recompute":
            with torch.no_grad():
                logits, value, state = self.net.step(x, self.state)
        else:
            logits, value, state = self.net.step(x, self.state)
            self.logits.append(logits)
            self.values_g.append(value)
            logits, value = logits.detach(), value.detach()
        probs = torch.softmax(logits, -1)
        actions = torch.multinomial(probs, 1).squeeze(1)
        self.actions.append(actions)
        self.values.append(value.numpy())
        return actions.numpy(), state

    def final_values(self, grid, agent, goals, state, idx):
        """``V`` of the final states of the environments ``idx`` (truncated)."""
        with torch.no_grad():
            x = self.planes.encode(grid[idx], agent[idx], None if goals is None else goals[idx])
            sel = torch.from_numpy(idx)
            return self.net.step(x, (state[0][sel], state[1][sel]))[1].numpy()

    def record(self, rewards, dones, state, weights=None):
        self.rewards[self.t] = rewards
        self.dones[self.t] = dones
        if weights is not None:
            self.weights[self.t] = weights
        keep = torch.from_numpy(1.0 - dones)[:, None]
        self.state = (state[0] * keep, state[1] * keep)
        self.t += 1

    def bootstrap(self, x):
        with torch.no_grad():
            return self.net.step(x, self.state)[1].numpy()

    def update(self, bootstrap, value_coef=0.5, entropy_coef=0.01, clip=0.5):
        steps, n = self.steps, self.n
        if self.path == "recompute":
            x = self.planes.view(self.buf)
            feats = self.net.trunk.features(x).view(steps, n, -1)
            h, c = self.init
            hs = []
            for t in range(steps):
                if t > 0:
                    keep = torch.from_numpy(1.0 - self.dones[t - 1])[:, None]
                    h, c = h * keep, c * keep
                h, c = self.net.trunk.core(feats[t], (h, c))
                hs.append(h)
            logits, values = self.net.heads(torch.cat(hs, 0))
        else:
            logits, values = torch.cat(self.logits, 0), torch.cat(self.values_g, 0)
        adv, ret = gae(
            self.rewards,
            np.stack(self.values),
            self.gamma * (1.0 - self.dones),
            bootstrap,
            self.lam,
        )
        loss = a2c_loss(
            logits,
            values,
            torch.cat(self.actions, 0),
            adv.reshape(-1),
            ret.reshape(-1),
            self.weights.reshape(-1),
            value_coef,
            entropy_coef,
        )
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.params, clip, foreach=True)
        self.opt.step()
        self.logits, self.values_g = [], []
        self.state = (self.state[0].detach(), self.state[1].detach())


class Env:
    """The project's Gymnasium vector env and its static geometry."""

    def __init__(self, maze: str, n: int, seed: int) -> None:
        env_id = f"worldgraph/MultiGoal-{maze.capitalize()}-v0"
        self.env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", threads=1)
        obs, _ = self.env.reset(seed=seed)
        self.grid, self.agent = obs["grid"], obs["agent"]
        self.n = n
        _, self.h, self.w = self.grid.shape
        self.wall = (self.grid[0] == WALL_CODE).reshape(-1)
        self.free = np.flatnonzero(~self.wall)
        self.timer = None

    def step(self, actions):
        obs, reward, terminated, truncated, _ = self.env.step(actions)
        self.grid, self.agent = obs["grid"], obs["agent"]
        return reward, terminated, truncated

    @property
    def final(self):
        f = self.env.unwrapped.final_obs
        return f["grid"], f["agent"]

    def cells(self, agent):
        return agent[:, 1].astype(np.int64) * self.w + agent[:, 0]

    def end_cells(self, done):
        """The cell each action led to (on an ended episode, its final cell)."""
        here = self.cells(self.agent)
        if done.any():
            fin = self.cells(self.final[1])
            here = np.where(done, fin, here)
        return here


class A2cDriver:
    """The A2C baseline (``hrl/baseline.rs``)."""

    goal_planes = 0

    def __init__(self, env, args, path, rng, channels_last):
        self.env = env
        self.planes = Planes(env.h, env.w, 0, channels_last)
        net = ActorCritic(self.planes.c, (16, 32), args.hidden, 3, env.h, env.w)
        if channels_last:
            net = net.to(memory_format=torch.channels_last)
        self.learner = EveryStep(net, self.planes, env.n, args.rollout, path, 0.99, 0.95, 7e-4, args.fused_adam)
        self.gamma = 0.99

    def iteration(self, tm: Timer):
        env, ln = self.env, self.learner
        ln.start()
        for _ in range(ln.steps):
            x = ln.encode(env.grid, env.agent, None)
            tm.lap("encode")
            actions, state = ln.act(x)
            tm.lap("act")
            r, term, trunc = env.step(actions)
            tm.lap("env")
            rewards = r.astype(np.float32)
            if trunc.any():
                idx = np.flatnonzero(trunc)
                g, a = env.final
                rewards[idx] += self.gamma * ln.final_values(g, a, None, state, idx)
            ln.record(rewards, (term | trunc).astype(np.float32), state)
            tm.mark()  # bookkeeping: "other"
        x = self.planes.encode(env.grid, env.agent)
        boot = ln.bootstrap(x)
        tm.lap("act")
        ln.update(boot)
        tm.lap("update")


class GcpDriver:
    """``π_g``'s training (``gcp/``): goal episodes of random free cells."""

    def __init__(self, env, args, path, rng, channels_last):
        self.env, self.rng = env, rng
        self.planes = Planes(env.h, env.w, 1, channels_last)
        net = ActorCritic(self.planes.c, (16, 32), args.hidden, 3, env.h, env.w)
        if channels_last:
            net = net.to(memory_format=torch.channels_last)
        self.learner = EveryStep(net, self.planes, env.n, args.rollout, path, 0.95, 0.95, 1e-3, args.fused_adam)
        self.gamma = 0.95
        self.time_limit = 4 * 6
        self.goals = self.draw(env.n)
        self.steps = np.zeros(env.n, np.int64)

    def draw(self, k):
        return self.env.free[self.rng.integers(0, len(self.env.free), size=k)].astype(np.int64)

    def iteration(self, tm: Timer):
        env, ln = self.env, self.learner
        ln.start()
        for _ in range(ln.steps):
            goals = self.goals[:, None]
            x = ln.encode(env.grid, env.agent, goals)
            tm.lap("encode")
            actions, state = ln.act(x)
            tm.lap("act")
            r, term, trunc = env.step(actions)
            tm.lap("env")
            ended = term | trunc
            self.steps += 1
            success = env.end_cells(ended) == self.goals
            timed_out = self.steps >= self.time_limit
            done = success | ended | timed_out
            rewards = np.where(success, 1.0 - 0.01, -0.01).astype(np.float32)
            cut = trunc & ~success & ~timed_out
            if cut.any():
                idx = np.flatnonzero(cut)
                g, a = env.final
                rewards[idx] += self.gamma * ln.final_values(g, a, goals, state, idx)
            if done.any():
                idx = np.flatnonzero(done)
                self.goals[idx] = self.draw(len(idx))
                self.steps[idx] = 0
            ln.record(rewards, done.astype(np.float32), state)
            tm.mark()  # bookkeeping: "other"
        boot = ln.bootstrap(self.planes.encode(env.grid, env.agent, self.goals[:, None]))
        tm.lap("act")
        ln.update(boot)
        tm.lap("update")


def covering_side(min_side, candidates, wall, width, height):
    """``wide_narrow::covering_side``: the smallest odd side ≥ ``min_side``
    whose windows around ``candidates`` cover every free cell."""
    first = max(min_side, 1) | 1
    widest = max(2 * max(width, height) + 1, first)
    for side in range(first, widest + 1, 2):
        cells, _ = window_cells(side, candidates, wall, width, height)
        reached = np.zeros(width * height, bool)
        reached[cells[cells >= 0]] = True
        if not (~wall & ~reached).any():
            return side
    return widest


def window_cells(side, centres, wall, width, height):
    """Grid cells of the ``side × side`` window slots around each centre
    (−1 outside the grid), and which slots are valid narrow goals."""
    r = side // 2
    k = np.arange(side * side)
    cx, cy = centres % width, centres // width
    x = cx[:, None] - r + (k % side)[None, :]
    y = cy[:, None] - r + (k // side)[None, :]
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    cells = np.where(inside, y * width + x, -1)
    valid = inside & ~wall[np.where(inside, cells, 0)]
    return cells, valid


class Manager(nn.Module):
    """The Wide-then-Narrow Manager (``hrl/feudal.rs``, ``wide_narrow.rs``)."""

    def __init__(self, height, width, candidates, window_len, hidden, cand_cells) -> None:
        super().__init__()
        self.trunk = Trunk(BASE_CHANNELS, (16, 32), hidden, height, width)
        self.value = nn.Linear(hidden, 1)
        self.wide_h = nn.Linear(hidden, candidates)
        # The goal map (``feudal::GoalMap``): conv 3×3 (8) → ReLU → conv 3×3
        # (1), its last layer zero, read at the candidates' cells.
        self.map1 = nn.Conv2d(BASE_CHANNELS, 8, 3, padding=1)
        self.map2 = nn.Conv2d(8, 1, 3, padding=1)
        nn.init.zeros_(self.map2.weight)
        nn.init.zeros_(self.map2.bias)
        self.register_buffer("cand_cells", torch.as_tensor(cand_cells, dtype=torch.int64))
        local = window_len * WINDOW_CHANNELS
        self.narrow_hidden = nn.Linear(hidden + local + candidates, hidden)
        self.narrow_out = nn.Linear(hidden, window_len)
        self.candidates = candidates

    def wide(self, h, x):
        """``π^ω`` logits: the core's, plus the goal map's at the candidates."""
        bias = self.map2(F.relu(self.map1(x))).flatten(1).index_select(1, self.cand_cells)
        return self.wide_h(h) + bias

    def narrow(self, h, wide, local, valid):
        which = F.one_hot(wide, self.candidates).to(h.dtype)
        x = F.relu(self.narrow_hidden(torch.cat([h, local, which], 1)))
        return self.narrow_out(x).masked_fill(~valid, MASKED_LOGIT)


class WnDriver:
    """The Wide-then-Narrow agent (``hrl/mod.rs``), without traversal."""

    def __init__(self, env, args, path, rng, channels_last):
        self.env, self.rng, self.args = env, rng, args
        n, h, w = env.n, env.h, env.w
        self.planes = Planes(h, w, 2, channels_last)
        self.mplanes = Planes(h, w, 0, channels_last)
        net = ActorCritic(self.planes.c, (16, 32), args.hidden, 3, h, w)
        self.cands = env.free[rng.choice(len(env.free), size=min(BENCH_CANDIDATES, len(env.free)), replace=False)]
        side = args.window or covering_side(7 if w > 25 else 5, self.cands, env.wall, w, h)
        self.side = side
        self.win_cells, self.win_valid = window_cells(side, self.cands, env.wall, w, h)
        self.manager = Manager(h, w, len(self.cands), side * side, args.hidden, self.cands)
        if channels_last:
            net = net.to(memory_format=torch.channels_last)
            self.manager = self.manager.to(memory_format=torch.channels_last)
        self.learner = EveryStep(net, self.planes, n, args.rollout, path, 0.99, 0.95, 7e-4, args.fused_adam)
        self.mparams = list(self.manager.parameters())
        self.mopt = make_optimizer(self.mparams, 7e-4, args.fused_adam)
        self.gamma, self.horizon = 0.99, args.horizon or max(args.rollout // 3, 1)
        self.mstate = self.manager.trunk.zeros(n)
        self.minit = self.manager.trunk.zeros(n)
        self.need = np.ones(n, bool)
        self.mreset = np.ones(n, bool)
        self.gw = np.full(n, -1, np.int64)
        self.gn = np.full(n, -1, np.int64)
        self.paid = np.zeros(n, bool)
        self.steps = np.zeros(n, np.int64)
        self.last = env.cells(env.agent)
        self.queues = [[] for _ in range(n)]
        self.irewards = np.zeros(n, np.float64)
        self.isteps = np.zeros(n, np.int64)
        #: Manager intervals that ended (its decisions, as the Rust bench counts them).
        self.decisions = 0

    def goal_marks(self):
        return np.stack([np.where(self.paid, -1, self.gw), self.gn], 1)

    def decide(self):
        """The Manager decides for the environments that need a goal."""
        who = np.flatnonzero(self.need)
        if len(who) == 0:
            return
        env = self.env
        grid, agent = env.grid[who].copy(), env.agent[who].copy()
        sel = torch.from_numpy(who)
        keep = torch.from_numpy(~self.mreset[who]).float()[:, None]
        with torch.no_grad():
            x = self.mplanes.encode(grid, agent)
            state = (self.mstate[0][sel] * keep, self.mstate[1][sel] * keep)
            h, c = self.manager.trunk.step(x, state)
            values = self.manager.value(h).squeeze(-1).numpy()
            wide = torch.multinomial(torch.softmax(self.manager.wide(h, x), -1), 1).squeeze(1)
            wide_np = wide.numpy()
            cells = self.win_cells[wide_np]
            valid = self.win_valid[wide_np].copy()
            here = env.cells(agent)
            codes = grid.reshape(len(who), -1)[np.arange(len(who))[:, None], np.maximum(cells, 0)]
            local = np.zeros((len(who), cells.shape[1], WINDOW_CHANNELS), np.float32)
            inside = cells >= 0
            local[..., :OBJECTS] = np.eye(OBJECTS, dtype=np.float32)[np.minimum(codes, OBJECTS - 1)] * inside[..., None]
            on_agent = cells == here[:, None]
            local[..., OBJECTS] = on_agent
            # The agent's own cell is no goal unless the window holds nothing else.
            drop = on_agent & valid & (valid.sum(1, keepdims=True) > 1)
            valid &= ~drop
            local = local.reshape(len(who), -1)
            logits = self.manager.narrow(h, wide, torch.from_numpy(local), torch.from_numpy(valid))
            narrow = torch.multinomial(torch.softmax(logits, -1), 1).squeeze(1).numpy()
        self.mstate[0][sel] = h
        self.mstate[1][sel] = c
        for j, e in enumerate(who):
            self.queues[e].append(
                {
                    "grid": grid[j],
                    "agent": agent[j],
                    "wide": int(wide_np[j]),
                    "narrow": int(narrow[j]),
                    "local": local[j],
                    "valid": valid[j],
                    "value": float(values[j]),
                    "reset": bool(self.mreset[e]),
                    "rewards": 0.0,
                    "k": 0,
                    "complete": False,
                    "ended": False,
                    "final": None,
                }
            )
        gw = self.cands[wide_np]
        self.gw[who] = gw
        self.gn[who] = cells[np.arange(len(who)), narrow]
        self.paid[who] = gw == here
        self.steps[who] = 0
        self.irewards[who] = 0.0
        self.isteps[who] = 0
        self.last[who] = here
        self.need[who] = False
        self.mreset[who] = False
        ws = self.learner.state
        keep = torch.ones(env.n, 1)
        keep[sel] = 0.0
        self.learner.state = (ws[0] * keep, ws[1] * keep)

    def manager_update(self):
        """The Manager's A2C over its decision queues (``Manager::loss``)."""
        b = len(self.queues)
        k_max = max(max(len(q) for q in self.queues), 1)
        n = k_max * b
        reset = np.zeros((k_max, b), np.float32)
        rewards = np.zeros((k_max, b), np.float32)
        discounts = np.zeros((k_max, b), np.float32)
        values = np.zeros((k_max, b), np.float32)
        weights = np.zeros((k_max, b), np.float32)
        wide = np.zeros((k_max, b), np.int64)
        narrow = np.zeros((k_max, b), np.int64)
        wl = self.side * self.side
        local = np.zeros((k_max, b, wl * WINDOW_CHANNELS), np.float32)
        valid = np.ones((k_max, b, wl), bool)
        grids = np.empty((k_max, b, self.env.h, self.env.w), np.uint8)
        agents = np.empty((k_max, b, 4), np.uint8)
        for e, q in enumerate(self.queues):
            for k in range(k_max):
                d = q[k] if k < len(q) else q[-1]
                grids[k, e], agents[k, e] = d["grid"], d["agent"]
                if k >= len(q):
                    continue
                reset[k, e] = d["reset"]
                values[k, e] = d["value"]
                wide[k, e], narrow[k, e] = d["wide"], d["narrow"]
                local[k, e], valid[k, e] = d["local"], d["valid"]
                if d["complete"]:
                    gk = self.gamma ** d["k"]
                    r = d["rewards"]
                    if d["ended"]:
                        rewards[k, e] = r + (gk * d["final"] if d["final"] is not None else 0.0)
                    else:
                        rewards[k, e], discounts[k, e] = r, gk
                    weights[k, e] = 1.0
                else:
                    rewards[k, e] = d["value"]
        m = self.manager
        x = self.mplanes.encode(grids.reshape(n, self.env.h, self.env.w), agents.reshape(n, 4))
        feats = m.trunk.features(x).view(k_max, b, -1)
        h, c = self.minit
        hs, cs = [], []
        for k in range(k_max):
            keep = torch.from_numpy(1.0 - reset[k])[:, None]
            h, c = m.trunk.core(feats[k], (h * keep, c * keep))
            hs.append(h)
            cs.append(c)
        hh = torch.cat(hs, 0)
        value = m.value(hh).squeeze(-1)
        wide_t = torch.from_numpy(wide.reshape(-1))
        lw = F.log_softmax(m.wide(hh, x), -1)
        ln_ = F.log_softmax(
            m.narrow(hh, wide_t, torch.from_numpy(local.reshape(n, -1)), torch.from_numpy(valid.reshape(n, -1))), -1
        )
        log_prob = lw.gather(1, wide_t[:, None]).squeeze(1) + ln_.gather(
            1, torch.from_numpy(narrow.reshape(-1))[:, None]
        ).squeeze(1)
        entropy = -(lw.exp() * lw).sum(-1) - (ln_.exp() * ln_).sum(-1)
        adv, ret = gae(rewards, values, discounts, np.zeros(b, np.float32), 0.95)
        if weights.sum() > 0:
            loss = a2c_loss(
                None, value, None, adv.reshape(-1), ret.reshape(-1), weights.reshape(-1), 0.5, 0.01, (log_prob, entropy)
            )
            self.mopt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.mparams, 0.5, foreach=True)
            self.mopt.step()
        nh, nc = [], []
        for e, q in enumerate(self.queues):
            if len(q) >= 2:
                nh.append(hs[len(q) - 2][e].detach())
                nc.append(cs[len(q) - 2][e].detach())
            else:
                nh.append(self.minit[0][e].detach())
                nc.append(self.minit[1][e].detach())
            del q[:-1]
        self.minit = (torch.stack(nh), torch.stack(nc))
        self.mstate = (self.mstate[0].detach(), self.mstate[1].detach())

    def iteration(self, tm: Timer):
        env, ln = self.env, self.learner
        ln.start()
        for _ in range(ln.steps):
            self.decide()
            tm.lap("manager")
            goals = self.goal_marks()
            x = ln.encode(env.grid, env.agent, goals)
            tm.lap("encode")
            actions, state = ln.act(x)
            tm.lap("act")
            r, term, trunc = env.step(actions)
            tm.lap("env")
            ended = term | trunc
            cell = env.end_cells(ended)
            self.steps += 1
            moved = cell != self.last
            self.last = cell
            reached = moved & (cell == self.gn)
            wide_now = moved & (cell == self.gw) & ~self.paid
            self.paid |= wide_now
            horizon_over = self.steps >= self.horizon
            over = reached | horizon_over | ended
            rewards = np.where(reached | wide_now, 1.0 - 0.01, -0.01).astype(np.float32)
            cut = trunc & ~reached & ~horizon_over
            if cut.any():
                idx = np.flatnonzero(cut)
                g, a = env.final
                rewards[idx] += self.gamma * ln.final_values(g, a, goals, state, idx)
            # The interval's task rewards and length, booked into its
            # decision when it ends.
            self.irewards += r
            self.isteps += 1
            cut_manager = []
            for e in np.flatnonzero(over):
                d = self.queues[e][-1]
                d["rewards"], d["k"] = float(self.irewards[e]), int(self.isteps[e])
                d["complete"], d["ended"] = True, bool(ended[e])
                if trunc[e] and not term[e]:
                    cut_manager.append(e)
            self.need |= over
            self.decisions += int(over.sum())
            self.mreset |= ended
            if cut_manager:
                idx = np.array(cut_manager)
                g, a = env.final
                with torch.no_grad():
                    sel = torch.from_numpy(idx)
                    hm, _ = self.manager.trunk.step(
                        self.mplanes.encode(g[idx], a[idx]), (self.mstate[0][sel], self.mstate[1][sel])
                    )
                    v = self.manager.value(hm).squeeze(-1).numpy()
                for e, ve in zip(cut_manager, v):
                    self.queues[e][-1]["final"] = float(ve)
            tm.lap("manager")
            ln.record(rewards, over.astype(np.float32), state)
            tm.mark()  # bookkeeping: "other"
        self.decide()
        tm.lap("manager")
        boot = ln.bootstrap(self.planes.encode(env.grid, env.agent, self.goal_marks()))
        tm.lap("act")
        ln.update(boot)
        tm.lap("update")
        self.manager_update()
        tm.lap("manager")


DRIVERS = {"a2c": A2cDriver, "gcp": GcpDriver, "wn": WnDriver}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agent", choices=sorted(DRIVERS), default="a2c", help="learner (default a2c)")
    p.add_argument("--maze", choices=["small", "medium", "large"], default="medium", help="maze (default medium)")
    p.add_argument("--envs", type=int, default=32, help="environments per update (default 32)")
    p.add_argument("--rollout", type=int, default=0, help="rollout length (default 16 for gcp, 60 otherwise)")
    p.add_argument("--threads", type=int, default=1, help="torch intra-op threads (default 1); interop threads: 1")
    p.add_argument("--seconds", type=float, default=6.0, help="seconds of measurement in total (default 6)")
    p.add_argument("--seed", type=int, default=0, help="seed of the environments and the weights")
    p.add_argument(
        "--path",
        choices=["best", "per-step", "recompute"],
        default="best",
        help="gradient path; best (default): both in alternating windows, the faster reported",
    )
    p.add_argument(
        "--layout",
        choices=["best", "nchw", "channels-last"],
        default="best",
        help="memory layout of the planes and convolutions; best (default): both, the faster reported",
    )
    p.add_argument(
        "--fused-adam",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="torch.optim.Adam(fused=True) (default on; off: foreach)",
    )
    p.add_argument("--hidden", type=int, default=128, help="width of the encoder output and the LSTM (default 128)")
    p.add_argument("--window", type=int, default=0, help="WN narrow window side (0: covering side, as the Rust agent)")
    p.add_argument(
        "--horizon", type=int, default=0, help="WN Manager horizon c in Worker steps (0: a third of the rollout, as Rust)"
    )
    args = p.parse_args(argv)
    if args.envs < 1 or args.threads < 1 or args.seconds <= 0:
        p.error("--envs and --threads must be ≥ 1, --seconds > 0")
    if args.rollout == 0:
        args.rollout = 16 if args.agent == "gcp" else 60
    torch.set_num_threads(args.threads)
    if torch.get_num_interop_threads() != 1:
        try:
            torch.set_num_interop_threads(1)
        except RuntimeError:  # set already in this process (tests call main twice)
            pass
    torch.manual_seed(args.seed)

    paths = ["per-step", "recompute"] if args.path == "best" else [args.path]
    layouts = ["nchw", "channels-last"] if args.layout == "best" else [args.layout]
    variants = [f"{p}/{l}" for p in paths for l in layouts]
    runs = {}
    for k, variant in enumerate(variants):
        path, layout = variant.split("/")
        rng = np.random.default_rng(args.seed)
        torch.manual_seed(args.seed)
        env = Env(args.maze, args.envs, args.seed + k)
        driver = DRIVERS[args.agent](env, args, path, rng, layout == "channels-last")
        driver.iteration(Timer())  # warm-up
        if args.agent == "wn":
            driver.decisions = 0
        runs[variant] = {"driver": driver, "rates": [], "wall": 0.0, "steps": 0, "iterations": 0, "times": Timer()}
    # Alternating windows, as the Rust bench measures its two paths.
    windows = 3
    window = args.seconds / (windows * len(variants))
    steps_per_iter = args.envs * args.rollout
    for _ in range(windows):
        for variant in variants:
            run = runs[variant]
            tm = run["times"]
            start = time.perf_counter()
            tm.mark()
            steps = 0
            while time.perf_counter() - start < window:
                run["driver"].iteration(tm)
                steps += steps_per_iter
                run["iterations"] += 1
            wall = time.perf_counter() - start
            run["rates"].append(steps / wall)
            run["wall"] += wall
            run["steps"] += steps
    figures = {}
    for variant, run in runs.items():
        rates = sorted(run["rates"])
        wall = max(run["wall"], 1e-9)
        shares = {k: v / wall for k, v in run["times"].t.items()}
        shares["other"] = max(0.0, 1.0 - sum(shares.values()))
        figures[variant] = {
            "env_steps_per_sec": rates[len(rates) // 2],
            "env_steps": run["steps"],
            "iterations": run["iterations"],
            "seconds": run["wall"],
            "phases": shares,
        }
        if args.agent == "wn":
            figures[variant]["manager_decisions_per_env_step"] = run["driver"].decisions / max(run["steps"], 1)
    best = max(figures, key=lambda k: figures[k]["env_steps_per_sec"])
    f = figures[best]
    d = runs[best]["driver"]
    env = d.env
    report = {
        "implementation": "pytorch",
        "agent": args.agent,
        "maze": args.maze,
        "grid": [env.w, env.h],
        "envs": args.envs,
        "rollout": args.rollout,
        "threads": torch.get_num_threads(),
        "interop_threads": torch.get_num_interop_threads(),
        "torch_version": torch.__version__,
        "python_version": sys.version.split()[0],
        "variant": best,
        "path": best.split("/")[0],
        "layout": best.split("/")[1],
        "fused_adam": args.fused_adam,
        "env_steps_per_sec": f["env_steps_per_sec"],
        "env_steps": f["env_steps"],
        "iterations": f["iterations"],
        "seconds": f["seconds"],
        "env_share": f["phases"]["env"],
        "phases": f["phases"],
        "variants": figures,
        "implements": implements(args, d),
    }
    if args.agent == "wn":
        report["manager_decisions_per_env_step"] = f["manager_decisions_per_env_step"]
        report["window_side"] = d.side
        report["horizon"] = d.horizon
        report["candidates"] = len(d.cands)
    print(json.dumps(report))
    return 0


def implements(args, d) -> str:
    base = (
        f"dense one-hot planes [N,{d.planes.c},H,W] -> conv3x3(16,s1)-relu-conv3x3(32,s2)-relu-linear({args.hidden})-relu "
        f"-> LSTMCell({args.hidden}) -> policy(3)+value; A2C with GAE(0.95), value 0.5, entropy 0.01, Adam, clip 0.5, "
        "truncated BPTT over the rollout"
    )
    if args.agent == "a2c":
        return "A2C baseline (gamma 0.99, lr 7e-4): " + base
    if args.agent == "gcp":
        return "pi_g (gamma 0.95, lr 1e-3, goal: a random free cell, 24-step limit): " + base
    return (
        "WN Worker (2 goal planes, gamma 0.99, lr 7e-4): "
        + base
        + f"; Manager: own trunk, value, wide head over {len(d.cands)} random candidates plus a goal map "
        "(conv3x3(8)-relu-conv3x3(1) at their cells), "
        f"narrow head over a {d.side}x{d.side} window, A2C over its decisions; no traversal"
    )


if __name__ == "__main__":
    sys.exit(main())
