//! `worldgraph._worldgraph`: the native half of the `worldgraph` Python
//! package. Two classes over the `sim` and `planner` crates:
//!
//! - [`Simulator`]: a `sim::BatchEnv` whose output buffers are NumPy arrays
//!   allocated once; every step writes the observations straight into them
//!   (no copy, stable addresses) with the GIL released, on the batch's own
//!   rayon threads.
//! - [`WorldGraph`]: a `planner::WorldGraph` (a `worldgraph discover` run's
//!   `graph.json`, or one built here from given nodes, its edges found with
//!   the doors open) and its dynamic-programming routes ([`Route`]).
//!
//! Arguments are checked here, in Python's words: integers through [`Int`]
//! (a `ValueError` naming the argument and its limits, never PyO3's bare
//! `OverflowError`), layouts through `parse_layout` (triple-quoted strings).
//!
//! The Gymnasium classes (`worldgraph.WorldGraphEnv`,
//! `worldgraph.WorldGraphVectorEnv`) are thin Python over these; see
//! `python/worldgraph/`.

use std::path::PathBuf;

use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray1,
    PyUntypedArray, PyUntypedArrayMethods,
};
use planner::{CellIdx, NodeId, PlannerConfig, PlannerError};
use pyo3::create_exception;
use pyo3::exceptions::{PyOverflowError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use sim::{
    AutoReset, BallSpawn, BatchEnv, EnvConfig, EnvMeta, Layout, LayoutError as SimLayoutError,
    LayoutErrorKind, Maze, SimError, Task,
};

// The exceptions say they live in `worldgraph` (which re-exports them), so
// that pickling finds them there: `_worldgraph` is no importable name.
create_exception!(
    worldgraph,
    LayoutError,
    PyValueError,
    "A maze layout was refused; the message names the line and column."
);
create_exception!(
    worldgraph,
    ClosedError,
    PyRuntimeError,
    "The simulator was closed; create a new one."
);
create_exception!(
    worldgraph,
    PlanError,
    PyValueError,
    "A world graph could not be loaded, built or queried (unknown node, no route, ...)."
);
create_exception!(
    worldgraph,
    DoorClosedError,
    PlanError,
    "A route passes a door that is closed or locked in the world the query describes: \
     a route through a door is refused while the door is closed (open it and ask again)."
);

fn sim_err(e: SimError) -> PyErr {
    match e {
        SimError::Layout(l) => LayoutError::new_err(l.to_string()),
        SimError::Io { .. } => pyo3::exceptions::PyOSError::new_err(e.to_string()),
        other => PyValueError::new_err(other.to_string()),
    }
}

fn plan_err(e: PlannerError) -> PyErr {
    match e {
        PlannerError::Io { .. } => pyo3::exceptions::PyOSError::new_err(e.to_string()),
        other => PlanError::new_err(other.to_string()),
    }
}

/// An integer argument as Python passed it (an `int`, a NumPy integer or
/// anything with `__index__`), kept whole so that a range check can name
/// the argument: PyO3's own conversion to a fixed-width type raises an
/// `OverflowError` that names nothing. `None` inside: beyond ±2**127, out
/// of every range here.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Int(Option<i128>);

impl<'a, 'py> FromPyObject<'a, 'py> for Int {
    type Error = PyErr;

    fn extract(obj: pyo3::Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        match obj.extract::<i128>() {
            Ok(v) => Ok(Int(Some(v))),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => Ok(Int(None)),
            Err(e) => Err(e),
        }
    }
}

impl Int {
    /// The value when it lies in `lo..=hi`, else a `ValueError` naming
    /// `name` and the limits, in Python's words.
    pub(crate) fn within(self, name: &str, lo: i128, hi: i128) -> PyResult<i128> {
        match self.0 {
            Some(v) if (lo..=hi).contains(&v) => Ok(v),
            Some(v) => Err(PyValueError::new_err(format!(
                "{name} must be an int from {lo} to {hi}, got {v}"
            ))),
            None => Err(PyValueError::new_err(format!(
                "{name} must be an int from {lo} to {hi}"
            ))),
        }
    }

    /// [`Int::within`] the range of `T`'s values from `lo` on.
    pub(crate) fn to<T>(self, name: &str, lo: T) -> PyResult<T>
    where
        T: Bounded + TryFrom<i128> + Into<i128>,
    {
        let v = self.within(name, lo.into(), T::MAX_I128)?;
        Ok(T::try_from(v).unwrap_or_else(|_| unreachable!("checked against the range of T")))
    }
}

/// The unsigned integer types arguments are read into, with their largest
/// value as an `i128` (usize's is platform-dependent).
pub(crate) trait Bounded {
    /// The largest value.
    const MAX_I128: i128;
}
macro_rules! bounded {
    ($($t:ty),*) => {$(impl Bounded for $t { const MAX_I128: i128 = <$t>::MAX as i128; })*};
}
bounded!(u8, u16, u32, u64);

fn parse_task(task: &str) -> PyResult<Task> {
    task.parse::<Task>().map_err(PyValueError::new_err)
}

fn parse_maze(maze: &str) -> PyResult<Maze> {
    Maze::ALL
        .into_iter()
        .find(|m| m.name().eq_ignore_ascii_case(maze))
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown maze {maze:?}: expected small, medium or large"
            ))
        })
}

/// Parses layout text as Python code usually holds it: a triple-quoted
/// string, whose first line is empty and whose rows may share an
/// indentation. Leading blank lines and the rows' common leading
/// whitespace are set aside before `sim` parses the rest; errors then name
/// the line and column of the text as given (1-based).
fn parse_layout(text: &str) -> Result<Layout, SimLayoutError> {
    let lines: Vec<&str> = text.split('\n').collect();
    let skipped = lines.iter().take_while(|l| l.trim().is_empty()).count();
    let rows = &lines[skipped..];
    let indent = rows
        .iter()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.len() - l.trim_start_matches([' ', '\t']).len())
        .min()
        .unwrap_or(0);
    // Only a prefix every non-blank row shares is removed (as textwrap.dedent).
    let prefix = rows
        .iter()
        .find(|l| !l.trim().is_empty())
        .map_or("", |l| &l[..indent]);
    let shared = rows
        .iter()
        .all(|l| l.trim().is_empty() || l.starts_with(prefix));
    let cut = if shared { indent } else { 0 };
    if skipped == 0 && cut == 0 {
        return Layout::parse("layout", text);
    }
    // Non-blank rows start with the prefix (ASCII whitespace), so `cut` is
    // a character boundary there; blank rows become empty.
    let body: Vec<&str> = rows
        .iter()
        .map(|l| if l.trim().is_empty() { "" } else { &l[cut..] })
        .collect();
    Layout::parse("layout", &body.join("\n")).map_err(|mut e| {
        let shift = |line: &mut usize, col: &mut usize| {
            if *line > 0 {
                *line += skipped;
                if *col > 0 {
                    *col += cut;
                }
            }
        };
        shift(&mut e.line, &mut e.col);
        if let LayoutErrorKind::TwoAgents {
            first_line,
            first_col,
        } = &mut e.kind
        {
            shift(first_line, first_col);
        }
        e
    })
}

/// The layout of a task: an embedded maze (its Door-Key variant for the
/// Door-Key task) or ASCII text.
fn layout_of(task: Task, maze: Option<&str>, layout: Option<&str>) -> PyResult<Layout> {
    match (maze, layout) {
        (_, Some(text)) => parse_layout(text).map_err(|e| LayoutError::new_err(e.to_string())),
        (Some(m), None) => Ok(parse_maze(m)?.layout(task.uses_door_key_layout())),
        (None, None) => Err(PyValueError::new_err("give a maze name or a layout")),
    }
}

/// The text of an embedded maze (`door_key`: its Door-Key variant).
#[pyfunction]
#[pyo3(signature = (maze, door_key=false))]
fn maze_text(maze: &str, door_key: bool) -> PyResult<&'static str> {
    Ok(parse_maze(maze)?.text(door_key))
}

/// Parses and validates an ASCII layout; returns `(width, height)` or
/// raises `LayoutError` naming the line and column.
#[pyfunction]
fn check_layout(text: &str) -> PyResult<(usize, usize)> {
    let l = parse_layout(text).map_err(|e| LayoutError::new_err(e.to_string()))?;
    Ok((l.width, l.height))
}

mod graph;
mod simulator;

use graph::{Route, WorldGraph, standable_cells};
use simulator::Simulator;

/// The native module.
#[pymodule]
fn _worldgraph(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Simulator>()?;
    m.add_class::<WorldGraph>()?;
    m.add_class::<Route>()?;
    m.add_function(wrap_pyfunction!(maze_text, m)?)?;
    m.add_function(wrap_pyfunction!(check_layout, m)?)?;
    m.add_function(wrap_pyfunction!(standable_cells, m)?)?;
    m.add("LayoutError", m.py().get_type::<LayoutError>())?;
    m.add("ClosedError", m.py().get_type::<ClosedError>())?;
    m.add("PlanError", m.py().get_type::<PlanError>())?;
    m.add("DoorClosedError", m.py().get_type::<DoorClosedError>())?;
    Ok(())
}
