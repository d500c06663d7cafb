"""Gymnasium environments over worldgraph's maze simulator.

- :class:`WorldGraphVectorEnv` (``gymnasium.vector.VectorEnv``): ``num_envs``
  mazes stepped in parallel by the Rust simulator, which writes the
  observations straight into NumPy arrays allocated once (zero copy: the
  arrays returned by ``reset`` and ``step`` are the same objects, rewritten
  in place every step; copy what you keep, or pass ``copy=True``). Stepping
  releases the GIL and runs on the batch's own threads. Finished episodes
  restart in the same step (``AutoresetMode.SAME_STEP``): the step's
  observation is the next episode's first, and ``infos["final_obs"]`` /
  ``infos["final_info"]`` hold the finished episode's last observation and
  info, as Gymnasium's ``SyncVectorEnv`` does in that mode.
- :class:`WorldGraphEnv` (``gymnasium.Env``): one maze, no auto-reset; a
  step after the episode's end raises ``gymnasium.error.ResetNeeded``.

Observations are a ``Dict``: ``"grid"``, the ``height × width`` uint8 cell
codes (0 floor, 1 wall, 2 ball, 3 key, 4 open door, 5 closed door, 6 locked
door, 7 exit, 8 lava), and ``"agent"``, uint8 ``[x, y, dir, carrying]``
(``dir`` 0 right, 1 down, 2 left, 3 up; ``carrying`` a cell code, 255 for
nothing). Actions use MiniGrid's numbering: 0 left, 1 right, 2 forward (the
MultiGoal tasks use these three), 3 pickup, 4 drop, 5 toggle (Door-Key uses
all six).

Integer arguments out of range raise ``ValueError`` naming the argument and
its limits; seeds may be NumPy integers (0 to 2**64 - 1). The environments
cannot be pickled or copied (their state lives in the Rust simulator): make
another with the same arguments and seed.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ClosedEnvironmentError, ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _worldgraph as _native

#: Number of distinct cell codes in ``obs["grid"]``.
NUM_OBJECTS = 9
#: ``obs["agent"][3]`` when the hands are empty.
CARRYING_NOTHING = 255
#: Cell codes by name.
OBJECTS = {
    "floor": 0,
    "wall": 1,
    "ball": 2,
    "key": 3,
    "door_open": 4,
    "door_closed": 5,
    "door_locked": 6,
    "exit": 7,
    "lava": 8,
}
#: MiniGrid's action numbering.
ACTIONS = {"left": 0, "right": 1, "forward": 2, "pickup": 3, "drop": 4, "toggle": 5}

_RENDER_MODES = ["rgb_array"]
#: Pixels per cell of rendered frames: the native renderer's limits.
CELL_PX = (2, 64)
_MAX_SEED = 2**64 - 1


def observation_space(width: int, height: int) -> spaces.Dict:
    """The observation space of one environment on a ``width × height`` maze."""
    return spaces.Dict(
        {
            "grid": spaces.Box(0, NUM_OBJECTS - 1, shape=(height, width), dtype=np.uint8),
            "agent": spaces.Box(
                low=np.zeros(4, dtype=np.uint8),
                high=np.array([width - 1, height - 1, 3, 255], dtype=np.uint8),
                shape=(4,),
                dtype=np.uint8,
            ),
        }
    )


def _new_seed(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**63 - 1))


def _check_render_args(render_mode: str | None, cell_px: int) -> None:
    if render_mode is not None and render_mode not in _RENDER_MODES:
        raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
    lo, hi = CELL_PX
    if isinstance(cell_px, bool) or not isinstance(cell_px, (int, np.integer)):
        raise TypeError(f"cell_px must be an int, got {type(cell_px).__name__}")
    if not lo <= cell_px <= hi:
        raise ValueError(f"cell_px must be an int from {lo} to {hi}, got {cell_px}")


def _seed_arg(seed: Any) -> int | None:
    """``reset``'s seed as a Python int (NumPy integers included, as
    Gymnasium's checks allow them and its seeding does not), or None."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise TypeError(
            f"seed must be one int (environment i is seeded from (seed, i)), got {type(seed).__name__}"
        )
    seed = int(seed)
    if not 0 <= seed <= _MAX_SEED:
        raise ValueError(f"seed must be an int from 0 to {_MAX_SEED}, got {seed}")
    return seed


class _OnSimulator:
    """What both environments do with the native batch they own."""

    _sim: _native.Simulator

    @property
    def simulator(self) -> _native.Simulator:
        """The native batch underneath (the vector env's arrays are its own)."""
        return self._sim

    def _check_open(self) -> None:
        if self._sim.closed:
            raise ClosedEnvironmentError("the environment is closed; make a new one")

    def __reduce_ex__(self, protocol: Any) -> Any:
        """Pickling and copying are refused (also ``copy.copy`` and
        ``copy.deepcopy``): the environments' state lives in the Rust
        simulator."""
        raise TypeError(
            f"{type(self).__name__} cannot be pickled or copied: its state lives in the Rust simulator; "
            "make another with the same arguments (gym.make / gym.make_vec) and reset it with the same seed"
        )


class WorldGraphEnv(_OnSimulator, gym.Env):
    """One maze environment (``gymnasium.Env``).

    Args:
        task: ``"multigoal"``, ``"multigoal-sparse"``, ``"multigoal-stochastic"``
            or ``"doorkey"``.
        maze: ``"small"``, ``"medium"`` or ``"large"`` (Door-Key uses the
            maze's Door-Key variant); ignored when ``layout`` is given.
        layout: an ASCII layout (``#`` wall, ``.`` floor, ``E`` exit, ``K``
            key, ``D`` locked door, ``C`` closed door, ``O`` open door, ``B``
            ball, ``L`` lava, ``> v < ^`` the agent's start and facing); a
            malformed one raises :class:`worldgraph.LayoutError`.
        max_steps: step limit (truncation); default twice the free cells.
        balls: balls spawned per episode in the MultiGoal tasks (default 5;
            0: only the layout's ``B`` cells).
        render_mode: ``None`` or ``"rgb_array"``.
        cell_px: pixels per cell of rendered frames (2 to 64).

    ``step`` returns ``info = {"balls": n}`` (balls collected so far). For
    episode statistics wrap the env in
    ``gymnasium.wrappers.RecordEpisodeStatistics`` (the env writes no
    ``"episode"`` key of its own). Once an episode ends, call ``reset()``:
    another step raises ``gymnasium.error.ResetNeeded``.
    """

    metadata = {"render_modes": _RENDER_MODES, "render_fps": 10}

    def __init__(
        self,
        task: str = "multigoal",
        maze: str | None = "small",
        layout: str | None = None,
        max_steps: int | None = None,
        balls: int | None = None,
        render_mode: str | None = None,
        cell_px: int = 16,
    ) -> None:
        _check_render_args(render_mode, cell_px)
        self._sim = _native.Simulator(
            task,
            maze=None if layout is not None else maze,
            layout=layout,
            num_envs=1,
            seed=0,
            threads=1,
            max_steps=max_steps,
            balls=balls,
            autoreset=False,
        )
        self.render_mode = render_mode
        self.cell_px = cell_px
        self.task = self._sim.task
        self.observation_space = observation_space(self._sim.width, self._sim.height)
        self.action_space = spaces.Discrete(self._sim.num_actions)
        self._seeded = False
        # How the episode ended ("terminated" or "truncated"), until reset().
        self._ended: str | None = None

    def _obs(self) -> dict[str, np.ndarray]:
        return {"grid": self._sim.grid[0].copy(), "agent": self._sim.agent[0].copy()}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Starts a new episode. ``seed`` (an int or NumPy integer, 0 to
        2**64 - 1) re-seeds the environment's own stream (the same seed gives
        the same episodes); ``options`` takes no keys."""
        self._check_open()
        seed = _seed_arg(seed)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}: none are supported")
        super().reset(seed=seed)
        if seed is not None:
            self._sim.reset(seed=seed)
        elif not self._seeded:
            self._sim.reset(seed=_new_seed(self.np_random))
        else:
            self._sim.reset()
        self._seeded = True
        self._ended = None
        return self._obs(), {}

    def step(self, action: int) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Takes one action (an int in ``0..num_actions``). After the step
        that ends an episode, raises ``ResetNeeded`` until ``reset()``."""
        self._check_open()
        if self._ended is not None:
            raise ResetNeeded(f"the episode ended ({self._ended}); call reset() before step()")
        if isinstance(action, np.ndarray) and action.shape == ():
            action = action.item()
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            raise TypeError(f"action must be an int, got {type(action).__name__}")
        self._sim.step([int(action)])
        s = self._sim
        terminated, truncated = bool(s.terminated[0]), bool(s.truncated[0])
        if terminated or truncated:
            self._ended = "terminated" if terminated else "truncated"
        return self._obs(), float(s.reward[0]), terminated, truncated, {"balls": int(s.balls[0])}

    def render(self) -> np.ndarray | None:
        """An RGB frame (``"rgb_array"`` mode), else None."""
        self._check_open()
        if self.render_mode == "rgb_array":
            return self._sim.render(0, self.cell_px)
        return None

    def close(self) -> None:
        """Releases the simulator; closing twice is allowed."""
        self._sim.close()
        super().close()


class WorldGraphVectorEnv(_OnSimulator, VectorEnv):
    """``num_envs`` maze environments stepped in parallel (``gymnasium.vector.VectorEnv``).

    Args:
        num_envs: number of environments.
        task, maze, layout, max_steps, balls, render_mode, cell_px: as
            :class:`WorldGraphEnv`.
        threads: threads stepping the batch, at least 1; more than the
            cores this process may use are capped at the cores (default:
            one per 256 environments, at most the cores; below a few
            hundred environments waking a second thread costs more than
            the step, and on a loaded machine one thread can beat two at
            any size). Results never depend on it: environment ``i`` draws
            from its own stream seeded by ``(seed, i)``.
        copy: return copies of the observation and reward arrays instead of
            the simulator's buffers (default False: zero copy; the arrays
            returned are rewritten by the next ``step``/``reset``).

    ``reset(seed=s)`` seeds environment ``i`` from ``(s, i)``. Same-step
    auto-reset: on a step that ends an episode, ``infos["final_obs"]`` is an
    object array holding that environment's last observation (None
    elsewhere, ``infos["_final_obs"]`` the mask) and ``infos["final_info"]``
    the finished episode's ``{"balls", "episode": {"r", "l"}}`` as batched
    arrays with masks (``"episode"`` as ``RecordEpisodeStatistics`` writes
    it for a single env). The batched final observation is also
    :attr:`final_obs` (valid where ``_final_obs``). Other steps' infos are
    empty. Gymnasium's vector observation wrappers (``FlattenObservation``
    and the like) refuse same-step auto-reset.
    """

    metadata = {"render_modes": _RENDER_MODES, "render_fps": 10, "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        task: str = "multigoal",
        maze: str | None = "small",
        layout: str | None = None,
        max_steps: int | None = None,
        balls: int | None = None,
        threads: int | None = None,
        render_mode: str | None = None,
        cell_px: int = 16,
        copy: bool = False,
    ) -> None:
        _check_render_args(render_mode, cell_px)
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive int, got {num_envs!r}")
        if threads is None:
            threads = max(1, min(os.cpu_count() or 1, num_envs // 256))
        self._sim = _native.Simulator(
            task,
            maze=None if layout is not None else maze,
            layout=layout,
            num_envs=int(num_envs),
            seed=_new_seed(np.random.default_rng()),
            threads=int(threads),
            max_steps=max_steps,
            balls=balls,
            autoreset=True,
        )
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.cell_px = cell_px
        self.copy = copy
        self.task = self._sim.task
        self.single_observation_space = observation_space(self._sim.width, self._sim.height)
        self.single_action_space = spaces.Discrete(self._sim.num_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        s = self._sim
        self._obs = {"grid": s.grid, "agent": s.agent}
        self.final_obs = {"grid": s.final_grid, "agent": s.final_agent}
        self._reward, self._terminated, self._truncated = s.reward, s.terminated, s.truncated

    def _observation(self) -> dict[str, np.ndarray]:
        if self.copy:
            return {"grid": self._obs["grid"].copy(), "agent": self._obs["agent"].copy()}
        return dict(self._obs)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Starts a new episode in every environment; ``seed`` (one int or
        NumPy integer, 0 to 2**64 - 1) seeds environment ``i`` from
        ``(seed, i)``. ``options`` takes no keys."""
        self._check_open()
        seed = _seed_arg(seed)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}: none are supported")
        super().reset(seed=seed)
        if seed is not None:
            self._sim.reset(seed=seed)
        else:
            self._sim.reset()
        return self._observation(), {}

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Steps every environment with its action (a 1-D integer array of
        ``num_envs`` values in ``0..num_actions``)."""
        self._check_open()
        ended = self._sim.step(actions)
        infos: dict[str, Any] = {}
        if ended:
            infos = self._final_infos()
        if self.copy:
            return (
                self._observation(),
                self._reward.copy(),
                self._terminated.copy(),
                self._truncated.copy(),
                infos,
            )
        return self._observation(), self._reward, self._terminated, self._truncated, infos

    def _final_infos(self) -> dict[str, Any]:
        s = self._sim
        done = s.terminated | s.truncated
        final_obs = np.full(self.num_envs, None, dtype=object)
        grid, agent = s.final_grid, s.final_agent
        for i in np.flatnonzero(done):
            final_obs[i] = {"grid": grid[i].copy(), "agent": agent[i].copy()}
        episode = {
            "r": np.where(done, s.episode_return, 0.0).astype(np.float32),
            "_r": done.copy(),
            "l": np.where(done, s.episode_length, 0).astype(np.int64),
            "_l": done.copy(),
        }
        final_info = {
            "balls": np.where(done, s.balls, 0).astype(np.int64),
            "_balls": done.copy(),
            "episode": episode,
            "_episode": done.copy(),
        }
        return {
            "final_obs": final_obs,
            "_final_obs": done,
            "final_info": final_info,
            "_final_info": done.copy(),
        }

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One RGB frame per environment (``"rgb_array"`` mode), else None."""
        self._check_open()
        if self.render_mode != "rgb_array":
            return None
        return tuple(self._sim.render(i, self.cell_px) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        """Releases the simulator (``close()`` calls it once)."""
        self._sim.close()
