//! [`WorldGraph`] and its [`Route`]s: a `planner::WorldGraph` and its
//! dynamic-programming routes (section 3.3).

use pyo3::types::{PyIterator, PyList, PyType};

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
    /// or ASCII layout: edges from random walks (seeded by `seed`), each
    /// shortened by an exact search, then all-pairs shortest paths. Cells
    /// the agent cannot stand on are dropped (as when a discover run's
    /// pivotal states are moved to the Door-Key variant of their maze).
    /// `task` decides the walks' rules (Door-Key: balls block, the key and
    /// doors work). `exhaustive=True` finds every edge random walks could
    /// ever find, by a search over states, instead of the walks: the edges
    /// that need the key fetched and the door opened on the way, which
    /// walks stopping at the first node they meet rarely find.
    #[staticmethod]
    #[pyo3(signature = (nodes, task="multigoal", maze=None, layout=None, seed=Int(Some(0)), exhaustive=false))]
    fn build(
        py: Python<'_>,
        nodes: Vec<(u16, u16)>,
        task: &str,
        maze: Option<&str>,
        layout: Option<&str>,
        seed: Int,
        exhaustive: bool,
    ) -> PyResult<WorldGraph> {
        let seed = seed.to::<u64>("seed", 0)?;
        let task = parse_task(task)?;
        let layout = layout_of(task, maze, layout)?;
        let mut cells = Vec::with_capacity(nodes.len());
        for (x, y) in nodes {
            if x as usize >= layout.width || y as usize >= layout.height {
                return Err(PlanError::new_err(format!(
                    "cell ({x}, {y}) is outside the {}x{} grid",
                    layout.width, layout.height
                )));
            }
            cells.push(CellIdx::from_xy(x as usize, y as usize, layout.width).0);
        }
        let given = planner::pivotal::nodes_from_cells(&layout, &cells);
        if given.is_empty() {
            return Err(PlanError::new_err("no node cell the agent can stand on"));
        }
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
            .detach(|| planner::WorldGraph::build(&layout, &cfg, &given))
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
    /// The graph's layout in its ASCII format.
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
    /// to node `target`, in the layout's initial world: the edges of the
    /// shortest path, each edge's recorded actions in turn, with the turns
    /// between edges. Raises `PlanError` for an unknown node or no path.
    #[pyo3(signature = (start, target, facing=Int(Some(0))))]
    fn route(&self, start: Int, target: Int, facing: Int) -> PyResult<Route> {
        let facing = facing.within("facing", 0, 3)? as u8;
        let mut r = planner::Route::with_capacity(256, 16);
        self.graph
            .route_into(self.node(start)?, facing, self.node(target)?, &mut r)
            .map_err(plan_err)?;
        Ok(self.route_object(&r))
    }

    /// The route from any pose `(x, y, dir)` to node `target`: the shortest
    /// way to the nearest node, then the graph route. `grid` (the
    /// observation's cell codes, `height × width`) and `carrying` (cell code,
    /// 255 nothing) describe the current world (open doors, key in hand);
    /// without them, the layout's initial world.
    #[pyo3(signature = (x, y, dir, target, grid=None, carrying=Int(Some(255))))]
    fn route_from_pose(
        &self,
        x: Int,
        y: Int,
        dir: Int,
        target: Int,
        grid: Option<Vec<u8>>,
        carrying: Int,
    ) -> PyResult<Route> {
        let l = self.graph.layout();
        let pose = sim::Pose {
            x: x.within("x", 0, l.width as i128 - 1)? as u16,
            y: y.within("y", 0, l.height as i128 - 1)? as u16,
            dir: dir.within("dir", 0, 3)? as u8,
        };
        let carrying = carrying.to::<u8>("carrying", 0)?;
        let world = match grid {
            Some(g) => {
                let l = self.graph.layout();
                if g.len() != l.width * l.height {
                    return Err(PyValueError::new_err(format!(
                        "grid has {} cells, the layout {}",
                        g.len(),
                        l.width * l.height
                    )));
                }
                self.graph.observe_world(&g, carrying)
            }
            None => self.graph.initial_world(),
        };
        let mut r = planner::Route::with_capacity(256, 16);
        self.graph
            .route_from_pose_into(pose, self.node(target)?, world, &mut r)
            .map_err(plan_err)?;
        Ok(self.route_object(&r))
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
