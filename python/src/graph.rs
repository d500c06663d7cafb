//! [`WorldGraph`] and its [`Route`]s: a `planner::WorldGraph` and its
//! dynamic-programming routes (section 3.3).
//!
//! ## Doors
//! One world graph per maze serves every task on it (the project's rule,
//! issue 47): [`WorldGraph::build`] finds the edges with every door of the
//! layout open ([`doors_passable`]), so routes through a door exist. A
//! route through a door is refused only while that door is closed: a query
//! given the observed `grid` raises `DoorClosedError` when the route enters
//! a door `grid` shows closed or locked ([`refuse_closed_doors`]); without
//! a grid the route is planned in the graph's own world.

use planner::RouteWorld;
use pyo3::types::{PyIterator, PyList, PyTuple, PyType};
use sim::Object;

use super::simulator::cell_px_arg;
use super::*;

/// A planned route: `actions[i]` is the `i`-th action (MiniGrid numbering)
/// and `cells[i]` the agent's `(x, y)` after it; `nodes` are the graph
/// nodes passed, first to target. A value: routes compare equal when all
/// four parts do, hash, pickle, and iterate over their actions.
#[pyclass(module = "worldgraph._worldgraph", frozen, eq, hash)]
#[derive(PartialEq, Eq, Hash)]
pub(crate) struct Route {
    /// `(x, y, dir)` the route starts from.
    #[pyo3(get)]
    start: (u16, u16, u8),
    /// Actions, MiniGrid numbering.
    actions: Vec<u8>,
    /// The agent's `(x, y)` after each action.
    #[pyo3(get)]
    cells: Vec<(u16, u16)>,
    /// Node ids passed, first to target.
    #[pyo3(get)]
    nodes: Vec<u16>,
}

/// The arguments of `Route(start, actions, cells, nodes)`, as pickling
/// passes them.
type RouteParts = ((u16, u16, u8), Vec<u32>, Vec<(u16, u16)>, Vec<u16>);

/// The largest action code (MiniGrid's `toggle`).
const MAX_ACTION: i128 = 5;

#[pymethods]
impl Route {
    /// A route from its parts, as a query returns them (pickling uses
    /// this): `start` `(x, y, dir)`, the `actions`, the `cells` after each
    /// action and the `nodes` passed. Values out of range raise `ValueError`.
    #[new]
    fn new(
        start: (Int, Int, Int),
        actions: Vec<Int>,
        cells: Vec<(Int, Int)>,
        nodes: Vec<Int>,
    ) -> PyResult<Route> {
        if actions.len() != cells.len() {
            return Err(PyValueError::new_err(format!(
                "actions and cells must have the same length, got {} and {}",
                actions.len(),
                cells.len()
            )));
        }
        let coord = |v: Int, name: String| v.to::<u16>(&name, 0);
        let start = (
            coord(start.0, "start[0]".into())?,
            coord(start.1, "start[1]".into())?,
            start.2.within("start[2]", 0, 3)? as u8,
        );
        let actions = actions
            .into_iter()
            .enumerate()
            .map(|(i, a)| Ok(a.within(&format!("actions[{i}]"), 0, MAX_ACTION)? as u8))
            .collect::<PyResult<_>>()?;
        let cells = cells
            .into_iter()
            .enumerate()
            .map(|(i, (x, y))| {
                Ok((
                    coord(x, format!("cells[{i}][0]"))?,
                    coord(y, format!("cells[{i}][1]"))?,
                ))
            })
            .collect::<PyResult<_>>()?;
        let nodes = nodes
            .into_iter()
            .enumerate()
            .map(|(i, n)| coord(n, format!("nodes[{i}]")))
            .collect::<PyResult<_>>()?;
        Ok(Route {
            start,
            actions,
            cells,
            nodes,
        })
    }

    /// Actions, MiniGrid numbering (a new list of ints on every access).
    #[getter]
    fn actions(&self) -> Vec<u32> {
        self.actions.iter().map(|&a| u32::from(a)).collect()
    }
    fn __len__(&self) -> usize {
        self.actions.len()
    }
    /// Iterates over the actions.
    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyIterator>> {
        PyList::new(py, self.actions())?.try_iter()
    }
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> (Bound<'py, PyType>, RouteParts) {
        let r = slf.get();
        (
            slf.get_type(),
            (r.start, r.actions(), r.cells.clone(), r.nodes.clone()),
        )
    }
    fn __repr__(&self) -> String {
        format!(
            "Route(start={:?}, {} actions, nodes={:?})",
            self.start,
            self.actions.len(),
            self.nodes
        )
    }
}

/// A world graph: pivotal states (nodes), edges with their recorded action
/// paths, and all-pairs shortest paths (the planner's dynamic programme).
#[pyclass(module = "worldgraph._worldgraph", frozen)]
pub(crate) struct WorldGraph {
    graph: planner::WorldGraph,
}

/// `layout` with every door open: the world a graph's edges are found in
/// (module docs, "Doors").
fn doors_passable(layout: &Layout) -> Layout {
    let mut open = layout.clone();
    for c in &mut open.cells {
        if Object::from_code(*c).is_some_and(Object::is_door) {
            *c = Object::DoorOpen as u8;
        }
    }
    open
}

/// The node cells of `WorldGraph.build`'s `nodes` argument, in the order
/// given, each inside the grid.
fn node_cells(nodes: &Bound<'_, PyAny>, layout: &Layout) -> PyResult<Vec<CellIdx>> {
    let mut cells = Vec::new();
    for (i, item) in nodes.try_iter()?.enumerate() {
        let item = item?;
        let not_a_pair = || {
            let shown = item.repr().map_or_else(|_| "?".into(), |r| r.to_string());
            PyValueError::new_err(format!(
                "nodes[{i}] must be an (x, y) pair of ints, got {shown}"
            ))
        };
        let pair: Vec<Bound<'_, PyAny>> = item.extract().map_err(|_| not_a_pair())?;
        let [x, y] = pair.as_slice() else {
            return Err(not_a_pair());
        };
        let (xi, yi) = (
            x.extract::<Int>().map_err(|_| not_a_pair())?,
            y.extract::<Int>().map_err(|_| not_a_pair())?,
        );
        let inside = |v: Int, side: usize| v.0.filter(|v| (0..side as i128).contains(v));
        match (inside(xi, layout.width), inside(yi, layout.height)) {
            (Some(cx), Some(cy)) => {
                cells.push(CellIdx::from_xy(cx as usize, cy as usize, layout.width));
            }
            _ => {
                return Err(PlanError::new_err(format!(
                    "cell ({x}, {y}) is outside the {}x{} grid",
                    layout.width, layout.height
                )));
            }
        }
    }
    Ok(cells)
}

/// The cells a world-graph node may occupy in a task's maze or layout:
/// floor, doors and exits the agent can reach from its start, doors
/// counted passable (module docs, "Doors"). `WorldGraph.build` refuses
/// any other cell.
#[pyfunction]
#[pyo3(signature = (task="multigoal", maze=None, layout=None))]
pub(crate) fn standable_cells(
    task: &str,
    maze: Option<&str>,
    layout: Option<&str>,
) -> PyResult<Vec<(u16, u16)>> {
    let layout = doors_passable(&layout_of(parse_task(task)?, maze, layout)?);
    Ok(planner::pivotal::v_all(&layout)
        .iter()
        .map(|c| c.xy(layout.width))
        .collect())
}

/// The first door a route enters that `grid` shows closed or locked, as
/// `DoorClosedError`.
fn refuse_closed_doors(route: &planner::Route, grid: &[u8], width: usize) -> PyResult<()> {
    for c in route.cells() {
        let object = Object::from_code(grid[c.index()]);
        if let Some(door @ (Object::DoorClosed | Object::DoorLocked)) = object {
            let (x, y) = c.xy(width);
            let (name, how) = match door {
                Object::DoorLocked => ("locked door", "open it with the key"),
                _ => ("closed door", "open it"),
            };
            return Err(DoorClosedError::new_err(format!(
                "the route passes the {name} at ({x}, {y}), closed in `grid`: a route \
                 through a door is refused while the door is closed; {how} and plan again"
            )));
        }
    }
    Ok(())
}

impl WorldGraph {
    fn node(&self, id: Int) -> PyResult<NodeId> {
        let n = self.graph.num_nodes();
        match id.0 {
            Some(v) if (0..n as i128).contains(&v) => Ok(NodeId(v as u16)),
            Some(v) => Err(PlanError::new_err(format!(
                "unknown node {v}: the graph has nodes 0..{n}"
            ))),
            None => Err(PlanError::new_err(format!(
                "unknown node: the graph has nodes 0..{n}"
            ))),
        }
    }

    fn route_object(&self, r: &planner::Route) -> Route {
        let w = self.graph.layout().width;
        let start = r.start().map_or((0, 0, 0), |p| (p.x, p.y, p.dir));
        Route {
            start,
            actions: r.actions().to_vec(),
            cells: r.cells().iter().map(|c| c.xy(w)).collect(),
            nodes: r.nodes().iter().map(|n| n.0).collect(),
        }
    }

    /// The observation grid `grid` (`height × width` or flat, any integer
    /// dtype, or nested lists) as cell codes in layout order, checked: the
    /// shape, the codes, and its walls against the graph's layout (walls
    /// never change, so a mismatch is a grid of another maze).
    fn grid_cells(&self, grid: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
        let py = grid.py();
        let l = self.graph.layout();
        let (w, h) = (l.width, l.height);
        let array = py
            .import("numpy")?
            .call_method1("asarray", (grid,))
            .map_err(|e| {
                PyValueError::new_err(format!(
                    "grid must be an integer array of shape ({h}, {w}): {}",
                    e.value(py)
                ))
            })?;
        let array = array.cast::<PyUntypedArray>()?;
        let kind = array.dtype().kind();
        if kind != b'i' && kind != b'u' {
            return Err(PyTypeError::new_err(format!(
                "grid must be an integer array (the observation's \"grid\"), got dtype {}",
                array.dtype().str()?
            )));
        }
        if array.shape() != [h, w] && array.shape() != [h * w] {
            return Err(PyValueError::new_err(format!(
                "grid must have shape ({h}, {w}) or ({},), got {:?}",
                h * w,
                PyTuple::new(py, array.shape())?
            )));
        }
        let flat = array
            .call_method1("reshape", (-1,))?
            .call_method1("astype", ("int64",))?;
        let flat = flat.extract::<PyReadonlyArray1<'_, i64>>()?;
        let wall = Object::Wall as u8;
        let mut cells = Vec::with_capacity(w * h);
        for (i, &v) in flat.as_array().iter().enumerate() {
            let (x, y) = (i % w, i / w);
            let code = u8::try_from(v)
                .ok()
                .filter(|&c| Object::from_code(c).is_some())
                .ok_or_else(|| {
                    PyValueError::new_err(format!(
                        "grid[{y}, {x}] is {v}: cell codes are 0 to {}",
                        sim::object::NUM_OBJECTS - 1
                    ))
                })?;
            if (code == wall) != (l.cells[i] == wall) {
                let what = if code == wall {
                    "is a wall where the graph's layout has none"
                } else {
                    "is no wall where the graph's layout has one"
                };
                return Err(PyValueError::new_err(format!(
                    "grid[{y}, {x}] {what}: grid is not of this graph's maze ({:?})",
                    l.name
                )));
            }
            cells.push(code);
        }
        Ok(cells)
    }

    /// Answers a route query: `query` plans into a route buffer in the
    /// world `grid` and `carrying` describe (without a grid, the graph's
    /// own), and the route is refused when it enters a door `grid` shows
    /// closed ([`refuse_closed_doors`]).
    fn plan(
        &self,
        grid: Option<&Bound<'_, PyAny>>,
        carrying: Int,
        query: impl FnOnce(RouteWorld, &mut planner::Route) -> Result<usize, PlannerError>,
    ) -> PyResult<Route> {
        let carrying = carrying.to::<u8>("carrying", 0)?;
        let cells = grid.map(|g| self.grid_cells(g)).transpose()?;
        let world = match &cells {
            Some(c) => self.graph.observe_world(c, carrying),
            None => self.graph.initial_world(),
        };
        let mut r = planner::Route::with_capacity(256, 16);
        query(world, &mut r).map_err(plan_err)?;
        if let Some(c) = &cells {
            refuse_closed_doors(&r, c, self.graph.layout().width)?;
        }
        Ok(self.route_object(&r))
    }
}

#[pymethods]
impl WorldGraph {
    /// Loads a graph saved by the planner (`graph.json` of a
    /// `worldgraph discover` run). Every edge is replayed in the simulator
    /// on load; a malformed file raises `PlanError`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<WorldGraph> {
        let graph = py
            .detach(|| planner::WorldGraph::load(&path))
            .map_err(plan_err)?;
        Ok(WorldGraph { graph })
    }

    /// A graph from the JSON text of [`WorldGraph::to_json`] (a saved
    /// file's content), checked as `load` checks a file.
    #[staticmethod]
    fn from_json(py: Python<'_>, text: &str) -> PyResult<WorldGraph> {
        let graph = py
            .detach(|| planner::WorldGraph::from_json("json", text))
            .map_err(plan_err)?;
        Ok(WorldGraph { graph })
    }

    /// The graph as the JSON text `save` writes.
    fn to_json(&self) -> String {
        self.graph.to_json()
    }

    /// Builds the graph over the given node cells `[(x, y), ...]` of a maze
    /// or ASCII layout, node `i` on `nodes[i]`: edges from random walks
    /// (seeded by `seed`), each shortened by an exact search, then
    /// all-pairs shortest paths. A cell no node may occupy (see
    /// `standable_cells`: walls, keys, balls, lava, cells cut off from the
    /// start), a duplicate or a cell outside the grid raises `PlanError`
    /// naming it. The edges are found with every door open, so a door cell
    /// may be a node (one graph per maze serves every task; a route
    /// through a door is refused while a query's `grid` shows it closed).
    /// `task` decides the walks' other rules (Door-Key: balls block, the
    /// key can be picked up).
    /// `exhaustive=True` finds every edge random walks could ever find, by
    /// a search over states, instead of the walks.
    #[staticmethod]
    #[pyo3(signature = (nodes, task="multigoal", maze=None, layout=None, seed=Int(Some(0)), exhaustive=false))]
    fn build(
        py: Python<'_>,
        nodes: &Bound<'_, PyAny>,
        task: &str,
        maze: Option<&str>,
        layout: Option<&str>,
        seed: Int,
        exhaustive: bool,
    ) -> PyResult<WorldGraph> {
        let seed = seed.to::<u64>("seed", 0)?;
        let task = parse_task(task)?;
        let layout = layout_of(task, maze, layout)?;
        let cells = node_cells(nodes, &layout)?;
        if cells.is_empty() {
            return Err(PlanError::new_err(
                "nodes is empty: give at least one (x, y) cell",
            ));
        }
        // Doors are passable in the graph's world, so a door cell may be a
        // node (routes to it are refused while it is closed).
        let open = doors_passable(&layout);
        let given = planner::pivotal::check_nodes(&open, &cells).map_err(plan_err)?;
        let cfg = PlannerConfig {
            candidates: planner::CandidateSet::Given,
            seed,
            // The walks follow the task's rules (`PlannerConfig::walk_task`:
            // MultiGoal-Stochastic walks as MultiGoal).
            task,
            shorten: true,
            edge_search: if exhaustive {
                planner::EdgeSearch::Exhaustive
            } else {
                planner::EdgeSearch::RandomWalks
            },
            ..PlannerConfig::default()
        };
        let graph = py
            .detach(|| planner::WorldGraph::build(&open, &cfg, &given))
            .map_err(plan_err)?;
        Ok(WorldGraph { graph })
    }

    /// Saves the graph as JSON (the planner's format), atomically.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.graph.save(&path).map_err(plan_err)
    }

    /// Pickles as its JSON text.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, (String,))> {
        Ok((
            slf.get_type().getattr("from_json")?,
            (slf.get().graph.to_json(),),
        ))
    }
    /// The graph is immutable: a copy is itself.
    fn __copy__(slf: Bound<'_, Self>) -> Bound<'_, Self> {
        slf
    }
    /// The graph is immutable: a deep copy is itself.
    fn __deepcopy__<'py>(slf: Bound<'py, Self>, _memo: &Bound<'py, PyAny>) -> Bound<'py, Self> {
        slf
    }

    /// Number of nodes.
    #[getter]
    fn num_nodes(&self) -> usize {
        self.graph.num_nodes()
    }
    /// The nodes (pivotal states) as `(x, y)`, by node id.
    #[getter]
    fn nodes(&self) -> Vec<(u16, u16)> {
        let w = self.graph.layout().width;
        self.graph.nodes().iter().map(|c| c.xy(w)).collect()
    }
    /// Edges as `(from, to, weight)`, weight = actions of the edge's path.
    #[getter]
    fn edges(&self) -> Vec<(u16, u16, u32)> {
        self.graph
            .edges()
            .iter()
            .map(|e| (e.from.0, e.to.0, e.weight()))
            .collect()
    }
    /// Columns of the graph's layout.
    #[getter]
    fn width(&self) -> usize {
        self.graph.layout().width
    }
    /// Rows of the graph's layout.
    #[getter]
    fn height(&self) -> usize {
        self.graph.layout().height
    }
    /// The graph's layout in its ASCII format: the world its edges were
    /// found in (a graph built here draws its doors open).
    #[getter]
    fn layout_text(&self) -> String {
        self.graph.layout().to_text()
    }
    /// The graph's layout's name.
    #[getter]
    fn layout_name(&self) -> String {
        self.graph.layout().name.clone()
    }
    /// The task whose rules the edge walks followed.
    #[getter]
    fn task(&self) -> &'static str {
        self.graph.config().task.name()
    }

    /// The node at cell `(x, y)`, or None (also outside the grid).
    fn node_at(&self, x: Int, y: Int) -> Option<u16> {
        let l = self.graph.layout();
        let x = x.0.filter(|v| (0..l.width as i128).contains(v))?;
        let y = y.0.filter(|v| (0..l.height as i128).contains(v))?;
        self.graph
            .node_at(CellIdx::from_xy(x as usize, y as usize, l.width))
            .map(|n| n.0)
    }

    /// Shortest distance (sum of edge weights) from node `a` to node `b`,
    /// or None when `b` cannot be reached.
    fn distance(&self, a: Int, b: Int) -> PyResult<Option<u32>> {
        let d = self.graph.distance(self.node(a)?, self.node(b)?);
        Ok((d != planner::UNREACHABLE).then_some(d))
    }

    /// The route from node `start` (standing there facing `facing`, 0 to 3)
    /// to node `target`: the edges of the shortest path, each edge's
    /// recorded actions in turn, with the turns between edges. Planned in
    /// the world `grid` (the observation's cell codes) and `carrying`
    /// describe, and refused with `DoorClosedError` when it enters a door
    /// `grid` shows closed or locked; without `grid`, in the graph's own
    /// world. Raises `PlanError` for an unknown node or no path.
    #[pyo3(signature = (start, target, facing=Int(Some(0)), grid=None, carrying=Int(Some(255))))]
    fn route(
        &self,
        start: Int,
        target: Int,
        facing: Int,
        grid: Option<&Bound<'_, PyAny>>,
        carrying: Int,
    ) -> PyResult<Route> {
        let facing = facing.within("facing", 0, 3)? as u8;
        let (start, target) = (self.node(start)?, self.node(target)?);
        self.plan(grid, carrying, |world, r| {
            self.graph
                .route_in_world_into(start, facing, target, world, r)
        })
    }

    /// The route from any pose `(x, y, dir)` to node `target`: the shortest
    /// way to the nearest node, then the graph route. `grid` (the
    /// observation's `height × width` cell codes, or flat) and `carrying`
    /// (cell code, 255 nothing) describe the current world: the doors it
    /// shows open or closed and the key in hand; a route entering a door
    /// it shows closed or locked raises `DoorClosedError`. The walls and
    /// the rest of the maze are the graph's layout's (a grid whose walls
    /// differ is refused). Without `grid`, the graph's own world.
    #[pyo3(signature = (x, y, dir, target, grid=None, carrying=Int(Some(255))))]
    fn route_from_pose(
        &self,
        x: Int,
        y: Int,
        dir: Int,
        target: Int,
        grid: Option<&Bound<'_, PyAny>>,
        carrying: Int,
    ) -> PyResult<Route> {
        let l = self.graph.layout();
        let pose = sim::Pose {
            x: x.within("x", 0, l.width as i128 - 1)? as u16,
            y: y.within("y", 0, l.height as i128 - 1)? as u16,
            dir: dir.within("dir", 0, 3)? as u8,
        };
        let target = self.node(target)?;
        self.plan(grid, carrying, |world, r| {
            self.graph.route_from_pose_into(pose, target, world, r)
        })
    }

    /// An RGB picture of the maze with the graph drawn on it; `cell_px`
    /// from 2 to 64.
    #[pyo3(signature = (cell_px=Int(Some(16))))]
    fn render<'py>(&self, py: Python<'py>, cell_px: Int) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let c = self.graph.render(cell_px_arg(cell_px)?);
        let (w, h) = (c.width, c.height);
        PyArray1::from_vec(py, c.rgb).reshape([h, w, 3])
    }

    fn __repr__(&self) -> String {
        format!(
            "WorldGraph(layout={:?}, {} nodes, {} edges)",
            self.graph.layout().name,
            self.graph.num_nodes(),
            self.graph.edges().len()
        )
    }
}
