//! [`Simulator`]: a `sim::BatchEnv` stepping into NumPy arrays allocated once.

use std::sync::{Mutex, MutexGuard};

use pyo3::sync::MutexExt;

use super::*;

/// A batch of maze environments stepped in parallel into NumPy arrays.
///
/// Every array attribute is allocated once and rewritten in place by
/// `reset` and `step` (their buffers never move): copy what you keep.
///
/// Thread-safe: the batch and its step records sit behind a mutex, taken
/// with the GIL released while waiting, so `step`, `reset`, `render` and
/// `close` called from several threads take turns (`close` waits for a
/// step in progress) instead of failing on a borrow.
#[pyclass(module = "worldgraph._worldgraph", frozen)]
pub(crate) struct Simulator {
    layout: Layout,
    cfg: EnvConfig,
    threads: usize,
    num_envs: usize,
    state: Mutex<State>,
    grid: Py<PyArray3<u8>>,
    agent: Py<PyArray2<u8>>,
    final_grid: Py<PyArray3<u8>>,
    final_agent: Py<PyArray2<u8>>,
    reward: Py<PyArray1<f32>>,
    terminated: Py<PyArray1<bool>>,
    truncated: Py<PyArray1<bool>>,
    episode_return: Py<PyArray1<f32>>,
    episode_length: Py<PyArray1<u32>>,
    balls: Py<PyArray1<u8>>,
}

/// What `step`, `reset` and `close` change, behind [`Simulator::state`].
struct State {
    /// `None` once closed.
    batch: Option<BatchEnv>,
    seed: u64,
    meta: Vec<EnvMeta>,
    actions: Vec<u8>,
}

/// The batch of [`State::batch`], or `ClosedError` once closed.
fn open(batch: &mut Option<BatchEnv>) -> PyResult<&mut BatchEnv> {
    batch
        .as_mut()
        .ok_or_else(|| ClosedError::new_err("the simulator is closed"))
}

/// The threads a batch may use: the cores this process may run on.
fn available_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Refuses a batch whose memory would exceed what the machine has
/// available (Linux's `MemAvailable`; elsewhere nothing is checked), with a
/// `MemoryError`: an allocation that fails in Rust aborts the interpreter.
fn check_memory(num_envs: usize, cells: usize) -> PyResult<()> {
    // Per environment: the simulator's state and grid, its step record and
    // action, and the NumPy buffers (grid and final grid, the small arrays).
    let per_env = std::mem::size_of::<sim::Env>()
        + cells
        + std::mem::size_of::<EnvMeta>()
        + 1
        + 2 * cells
        + 8
        + 4
        + 2
        + 8
        + 1;
    let needed = (num_envs as u128) * (per_env as u128);
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemAvailable:"))?;
        let kib: u128 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib * 1024)
    });
    match available {
        Some(avail) if needed > avail => Err(pyo3::exceptions::PyMemoryError::new_err(format!(
            "num_envs={num_envs} needs about {:.1} GB for a {cells}-cell maze; {:.1} GB are available",
            needed as f64 / 1e9,
            avail as f64 / 1e9
        ))),
        _ => Ok(()),
    }
}

impl Simulator {
    /// Takes the state, waiting (with the GIL released) while another
    /// thread holds it.
    fn state(&self, py: Python<'_>) -> PyResult<MutexGuard<'_, State>> {
        self.state.lock_py_attached(py).map_err(|_| {
            PyRuntimeError::new_err("the simulator failed in another thread and cannot be used")
        })
    }

    /// Converts and checks an action array into `st.actions`.
    fn load_actions(&self, st: &mut State, actions: &Bound<'_, PyAny>) -> PyResult<()> {
        let n = self.num_envs;
        let task = self.cfg.task;
        let num_actions = task.num_actions() as i64;
        let check = move |i: usize, v: i64| -> PyResult<u8> {
            if (0..num_actions).contains(&v) {
                Ok(v as u8)
            } else {
                Err(PyValueError::new_err(format!(
                    "action {v} of environment {i} is out of range: the {} task has actions 0..={}",
                    task,
                    num_actions - 1
                )))
            }
        };
        if let Ok(arr) = actions.cast::<PyUntypedArray>() {
            if arr.ndim() != 1 || arr.len() != n {
                return Err(PyValueError::new_err(format!(
                    "actions must have shape ({n},), got {:?}",
                    arr.shape()
                )));
            }
            let dtype = arr.dtype();
            let kind = dtype.kind();
            if kind != b'i' && kind != b'u' {
                return Err(PyTypeError::new_err(format!(
                    "actions must be an integer array, got dtype {}",
                    dtype.str()?
                )));
            }
            // The common dtypes are read in place; the others go through int64.
            macro_rules! read_as {
                ($t:ty) => {
                    if let Ok(a) = actions.extract::<PyReadonlyArray1<'_, $t>>() {
                        for (i, (&v, out)) in
                            a.as_array().iter().zip(st.actions.iter_mut()).enumerate()
                        {
                            *out = check(i, v as i64)?;
                        }
                        return Ok(());
                    }
                };
            }
            read_as!(u8);
            read_as!(i64);
            read_as!(i32);
            // Any other integer dtype: through int64 (NumPy converts).
            let a64 = actions.call_method1("astype", ("int64",))?;
            let a = a64.extract::<PyReadonlyArray1<'_, i64>>()?;
            for (i, (&v, out)) in a.as_array().iter().zip(st.actions.iter_mut()).enumerate() {
                *out = check(i, v)?;
            }
            return Ok(());
        }
        // A list or tuple of Python ints.
        let values: Vec<Bound<'_, PyAny>> = actions.extract().map_err(|_| {
            PyTypeError::new_err(format!(
                "actions must be a 1-D integer array or a sequence of {n} ints, got {}",
                actions
                    .get_type()
                    .name()
                    .map(|s| s.to_string())
                    .unwrap_or_default()
            ))
        })?;
        if values.len() != n {
            return Err(PyValueError::new_err(format!(
                "actions must have shape ({n},), got ({},)",
                values.len()
            )));
        }
        for (i, v) in values.iter().enumerate() {
            if v.is_instance_of::<pyo3::types::PyBool>()
                || v.is_instance_of::<pyo3::types::PyFloat>()
            {
                return Err(PyTypeError::new_err(format!(
                    "action of environment {i} must be an int, got {}",
                    v.get_type().name()?
                )));
            }
            let x: Int = v.extract().map_err(|_| {
                PyTypeError::new_err(format!("action of environment {i} must be an int"))
            })?;
            st.actions[i] = match x.0.and_then(|x| i64::try_from(x).ok()) {
                Some(x) => check(i, x)?,
                None => {
                    return Err(PyValueError::new_err(format!(
                        "action {v} of environment {i} is out of range: the {task} task has actions 0..={}",
                        num_actions - 1
                    )));
                }
            };
        }
        Ok(())
    }

    /// Copies the small per-environment records of `meta` into the arrays.
    fn scatter(&self, py: Python<'_>, meta: &[EnvMeta], ended: bool) -> PyResult<()> {
        let mut agent = self.agent.bind(py).readwrite();
        let mut reward = self.reward.bind(py).readwrite();
        let mut term = self.terminated.bind(py).readwrite();
        let mut trunc = self.truncated.bind(py).readwrite();
        let mut fa = self.final_agent.bind(py).readwrite();
        let mut ret = self.episode_return.bind(py).readwrite();
        let mut len = self.episode_length.bind(py).readwrite();
        let mut balls = self.balls.bind(py).readwrite();
        let (agent, reward, term, trunc) = (
            agent.as_slice_mut()?,
            reward.as_slice_mut()?,
            term.as_slice_mut()?,
            trunc.as_slice_mut()?,
        );
        let (fa, ret, len, balls) = (
            fa.as_slice_mut()?,
            ret.as_slice_mut()?,
            len.as_slice_mut()?,
            balls.as_slice_mut()?,
        );
        py.detach(|| {
            for (i, m) in meta.iter().enumerate() {
                agent[i * 4..i * 4 + 4].copy_from_slice(&[m.x as u8, m.y as u8, m.dir, m.carrying]);
                reward[i] = m.reward;
                term[i] = m.terminated();
                trunc[i] = m.truncated();
                ret[i] = m.episode_return;
                len[i] = m.episode_len;
                balls[i] = m.balls;
                if ended || m.done() {
                    fa[i * 4..i * 4 + 4].copy_from_slice(&[
                        m.end_x as u8,
                        m.end_y as u8,
                        m.end_dir,
                        m.end_carrying,
                    ]);
                }
            }
        });
        Ok(())
    }
}

#[pymethods]
impl Simulator {
    /// `num_envs` environments of `task` on an embedded `maze` (small,
    /// medium, large; Door-Key uses the maze's Door-Key variant) or on an
    /// ASCII `layout`. Environment `i` draws from its own stream seeded by
    /// `(seed, i)`, so results never depend on `threads`, which is capped
    /// at the cores this process may use. `max_steps` defaults to twice the
    /// free cells; `balls` (MultiGoal tasks) to 5 random balls per episode
    /// (0: only the layout's `B` cells). `autoreset=True` starts the next
    /// episode in the step that ends one (the final state stays in
    /// `final_grid` / `final_agent`). An integer out of range raises
    /// `ValueError` naming it and its limits.
    #[new]
    #[pyo3(signature = (task, maze=None, layout=None, num_envs=Int(Some(1)), seed=Int(Some(0)), threads=Int(Some(1)), max_steps=None, balls=None, autoreset=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        task: &str,
        maze: Option<&str>,
        layout: Option<&str>,
        num_envs: Int,
        seed: Int,
        threads: Int,
        max_steps: Option<Int>,
        balls: Option<Int>,
        autoreset: bool,
    ) -> PyResult<Simulator> {
        let n = num_envs.to::<u32>("num_envs", 1)? as usize;
        let seed = seed.to::<u64>("seed", 0)?;
        let threads = (threads.to::<u32>("threads", 1)? as usize).min(available_cores());
        let task = parse_task(task)?;
        let layout = layout_of(task, maze, layout)?;
        let mut cfg = EnvConfig::for_task(task, &layout);
        if let Some(m) = max_steps {
            cfg.max_steps = m.to::<u32>("max_steps", 1)?;
        }
        if let Some(b) = balls {
            cfg.balls = match b.to::<u8>("balls", 0)? {
                0 => BallSpawn::Layout,
                b => BallSpawn::Random(b),
            };
        }
        cfg.auto_reset = if autoreset {
            AutoReset::SameStep
        } else {
            AutoReset::Off
        };
        check_memory(n, layout.cells.len())?;
        let batch = BatchEnv::new(layout.clone(), cfg, n, seed, threads).map_err(sim_err)?;
        let (h, w) = (layout.height, layout.width);
        let sim = Simulator {
            layout,
            cfg,
            threads,
            num_envs: n,
            state: Mutex::new(State {
                batch: Some(batch),
                seed,
                meta: vec![EnvMeta::EMPTY; n],
                actions: vec![0; n],
            }),
            grid: PyArray3::zeros(py, [n, h, w], false).unbind(),
            agent: PyArray2::zeros(py, [n, 4], false).unbind(),
            final_grid: PyArray3::zeros(py, [n, h, w], false).unbind(),
            final_agent: PyArray2::zeros(py, [n, 4], false).unbind(),
            reward: PyArray1::zeros(py, [n], false).unbind(),
            terminated: PyArray1::zeros(py, [n], false).unbind(),
            truncated: PyArray1::zeros(py, [n], false).unbind(),
            episode_return: PyArray1::zeros(py, [n], false).unbind(),
            episode_length: PyArray1::zeros(py, [n], false).unbind(),
            balls: PyArray1::zeros(py, [n], false).unbind(),
        };
        sim.reset(py, None)?;
        Ok(sim)
    }

    /// Starts a new episode in every environment and writes the first
    /// observations. With `seed` (0 to 2**64 - 1), the batch is re-seeded
    /// first (environment `i` from `(seed, i)`); without, every environment
    /// continues its stream.
    #[pyo3(signature = (seed=None))]
    fn reset(&self, py: Python<'_>, seed: Option<Int>) -> PyResult<()> {
        let seed = seed.map(|s| s.to::<u64>("seed", 0)).transpose()?;
        let mut guard = self.state(py)?;
        let st = &mut *guard;
        open(&mut st.batch)?;
        if let Some(s) = seed {
            st.batch = Some(
                BatchEnv::new(
                    self.layout.clone(),
                    self.cfg,
                    self.num_envs,
                    s,
                    self.threads,
                )
                .map_err(sim_err)?,
            );
            st.seed = s;
        }
        {
            let mut grid = self.grid.bind(py).readwrite();
            let mut finals = self.final_grid.bind(py).readwrite();
            let (cells, final_cells) = (grid.as_slice_mut()?, finals.as_slice_mut()?);
            let batch = open(&mut st.batch)?;
            let meta = &mut st.meta;
            py.detach(|| {
                batch.reset(sim::StepOut {
                    cells,
                    final_cells,
                    meta,
                })
            });
        }
        self.scatter(py, &st.meta, true)
    }

    /// Steps environment `i` with `actions[i]` (a 1-D integer array or
    /// sequence of `num_envs` actions in `0..num_actions`), in parallel and
    /// with the GIL released; returns how many episodes ended.
    fn step(&self, py: Python<'_>, actions: &Bound<'_, PyAny>) -> PyResult<usize> {
        let mut guard = self.state(py)?;
        let st = &mut *guard;
        open(&mut st.batch)?;
        self.load_actions(st, actions)?;
        let ended = {
            let mut grid = self.grid.bind(py).readwrite();
            let mut finals = self.final_grid.bind(py).readwrite();
            let (cells, final_cells) = (grid.as_slice_mut()?, finals.as_slice_mut()?);
            let batch = open(&mut st.batch)?;
            let (meta, actions) = (&mut st.meta, &st.actions);
            py.detach(|| {
                batch.step(
                    actions,
                    sim::StepOut {
                        cells,
                        final_cells,
                        meta,
                    },
                )
            })
        };
        self.scatter(py, &st.meta, false)?;
        Ok(ended)
    }

    /// An RGB picture (`H·cell_px × W·cell_px × 3`, uint8) of environment
    /// `index` (0 to `num_envs - 1`) as its observation stands; `cell_px`
    /// from 2 to 64.
    #[pyo3(signature = (index=Int(Some(0)), cell_px=Int(Some(16))))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        index: Int,
        cell_px: Int,
    ) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let index = index.within("index", 0, self.num_envs as i128 - 1)? as usize;
        let cell_px = cell_px_arg(cell_px)?;
        let mut st = self.state(py)?;
        open(&mut st.batch)?;
        let (w, h) = (self.layout.width, self.layout.height);
        let grid = self.grid.bind(py).readonly();
        let cells = &grid.as_slice()?[index * w * h..(index + 1) * w * h];
        let canvas = sim::render::render_env(cells, w, h, &st.meta[index], cell_px);
        let (cw, ch) = (canvas.width, canvas.height);
        PyArray1::from_vec(py, canvas.rgb).reshape([ch, cw, 3])
    }

    /// Releases the environments; every later call raises `ClosedError`.
    /// A step in progress in another thread finishes first. Closing twice
    /// is allowed.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.state(py)?.batch = None;
        Ok(())
    }

    /// Pickling and copying are refused: the environments' state lives in
    /// the Rust batch. Make another simulator with the same arguments.
    fn __reduce__(&self) -> PyResult<()> {
        Err(PyTypeError::new_err(
            "Simulator cannot be pickled or copied: its environments live in Rust; \
             make another with the same arguments (and reset it with the same seed)",
        ))
    }

    /// True after `close()`.
    #[getter]
    fn closed(&self, py: Python<'_>) -> PyResult<bool> {
        Ok(self.state(py)?.batch.is_none())
    }
    /// Number of environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }
    /// Columns of the maze.
    #[getter]
    fn width(&self) -> usize {
        self.layout.width
    }
    /// Rows of the maze.
    #[getter]
    fn height(&self) -> usize {
        self.layout.height
    }
    /// Actions of the task: 3 (left, right, forward) for the MultiGoal
    /// tasks, 6 (plus pickup, drop, toggle) for Door-Key.
    #[getter]
    fn num_actions(&self) -> usize {
        self.cfg.task.num_actions()
    }
    /// The task's name.
    #[getter]
    fn task(&self) -> &'static str {
        self.cfg.task.name()
    }
    /// Step limit of an episode (reaching it truncates).
    #[getter]
    fn max_steps(&self) -> u32 {
        self.cfg.max_steps
    }
    /// Threads stepping the batch (the number asked for, capped at the cores).
    #[getter]
    fn threads(&self) -> usize {
        self.threads
    }
    /// The seed of the last seeding.
    #[getter]
    fn seed(&self, py: Python<'_>) -> PyResult<u64> {
        Ok(self.state(py)?.seed)
    }
    /// The layout in its ASCII format (agent at its start).
    #[getter]
    fn layout_text(&self) -> String {
        self.layout.to_text()
    }
    /// The layout's name.
    #[getter]
    fn layout_name(&self) -> String {
        self.layout.name.clone()
    }
    /// `(num_envs, height, width)` uint8 cell codes of the observations
    /// (0 floor, 1 wall, 2 ball, 3 key, 4 open door, 5 closed door, 6
    /// locked door, 7 exit, 8 lava); the agent is in `agent`.
    #[getter]
    fn grid<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<u8>> {
        self.grid.bind(py).clone()
    }
    /// `(num_envs, 4)` uint8: the agent's column, row, facing (0 right, 1
    /// down, 2 left, 3 up) and carried object's cell code (255: nothing).
    #[getter]
    fn agent<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u8>> {
        self.agent.bind(py).clone()
    }
    /// `(num_envs, height, width)`: the grid each episode ended on, written
    /// for the environments whose episode the last step ended (stale
    /// elsewhere).
    #[getter]
    fn final_grid<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<u8>> {
        self.final_grid.bind(py).clone()
    }
    /// `(num_envs, 4)`: the pose the last action led to, before any
    /// auto-reset (as `agent`).
    #[getter]
    fn final_agent<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u8>> {
        self.final_agent.bind(py).clone()
    }
    /// `(num_envs,)` float32 rewards of the last step.
    #[getter]
    fn reward<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.reward.bind(py).clone()
    }
    /// `(num_envs,)` bool: the last step ended the episode by the task's rule
    /// (exit, lava).
    #[getter]
    fn terminated<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        self.terminated.bind(py).clone()
    }
    /// `(num_envs,)` bool: the last step reached the step limit.
    #[getter]
    fn truncated<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        self.truncated.bind(py).clone()
    }
    /// `(num_envs,)` float32: return of the episode so far, or of the
    /// finished one where the last step ended it.
    #[getter]
    fn episode_return<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f32>> {
        self.episode_return.bind(py).clone()
    }
    /// `(num_envs,)` uint32: steps of the episode so far, or of the
    /// finished one where the last step ended it.
    #[getter]
    fn episode_length<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u32>> {
        self.episode_length.bind(py).clone()
    }
    /// `(num_envs,)` uint8: balls collected in the episode (or the finished one).
    #[getter]
    fn balls<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u8>> {
        self.balls.bind(py).clone()
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let st = self.state(py)?;
        Ok(format!(
            "Simulator(task={:?}, layout={:?}, num_envs={}, threads={}, seed={}{})",
            self.cfg.task.name(),
            self.layout.name,
            self.num_envs,
            self.threads,
            st.seed,
            if st.batch.is_none() { ", closed" } else { "" }
        ))
    }
}

/// The `cell_px` argument of the pictures: 2 to 64 pixels a cell.
pub(crate) fn cell_px_arg(cell_px: Int) -> PyResult<usize> {
    Ok(cell_px.within("cell_px", 2, 64)? as usize)
}
