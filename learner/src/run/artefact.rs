//! The discovery run as an artefact of stage 1 that stage 2 reads: its
//! directory holds the identity it was started with (`config.toml`), the
//! world graph over `V_p` (`graph.json`, section 3.3) and `π_g`
//! (`pi_g.json`, `pi_g.ot`, section 3.2). This module is the one place
//! that knows that layout: [`DiscoveryIdentity`] for `discover` itself,
//! [`recorded_layout`] and [`check_world_graph_layout`] for whoever points
//! a run at it, and the hand-off from stage 1 to stage 2
//! ([`load_gcp`], [`world_graph_for`], [`build_agent`]).

use std::path::Path;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};
use sim::{Layout, Maze, Task};

use crate::discovery::DiscoveryConfig;
use crate::gcp::{GcpConfig, GoalConditionedPolicy};
use crate::hrl::wide_narrow::wide_goal_candidates;
use crate::hrl::{Agent, AgentConfig, AgentKind, Candidates, WorldGraphInputs};

/// The world graph's file in a discovery run.
pub const GRAPH_FILE: &str = "graph.json";
/// `π_g`'s configuration in a discovery run.
pub const GCP_CONFIG_FILE: &str = "pi_g.json";
/// `π_g`'s weights in a discovery run.
pub const GCP_WEIGHTS_FILE: &str = "pi_g.ot";

/// What a discovery run was started with (`<run>/config.toml`): the
/// layout (name, size, FNV-1a digest of its cells) and the resolved
/// settings with their digest. A resumed run must match it, budget aside.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscoveryIdentity {
    layout: String,
    layout_size: String,
    layout_digest: String,
    envs: usize,
    config_digest: String,
    discovery: DiscoveryConfig,
}

fn fnv1a(bytes: &[u8]) -> String {
    let h = bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    format!("{h:016x}")
}

/// Whether `text` is a discover run's `config.toml` (its identity).
pub fn is_run_identity(text: &str) -> bool {
    toml::from_str::<DiscoveryIdentity>(text).is_ok()
}

/// The layout a discover run was made on, as it recorded it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedLayout {
    /// The layout's name (`small`, or a layout file's name).
    pub name: String,
    /// Width in cells.
    pub width: usize,
    /// Height in cells.
    pub height: usize,
}

/// The layout of the discover run in `dir`: from its identity
/// (`config.toml`), else from its world graph (`graph.json`).
pub fn recorded_layout(dir: &Path) -> Option<RecordedLayout> {
    if let Ok(id) = DiscoveryIdentity::read(dir) {
        let (w, h) = id.layout_size.split_once('x')?;
        return Some(RecordedLayout {
            name: id.layout,
            width: w.parse().ok()?,
            height: h.parse().ok()?,
        });
    }
    let graph = planner::WorldGraph::load(&dir.join(GRAPH_FILE)).ok()?;
    let l = graph.layout();
    Some(RecordedLayout {
        name: l.name.clone(),
        width: l.width,
        height: l.height,
    })
}

/// Refuses the world graph of the discover run `dir` for a run on `maze`
/// (whose layout is `layout`) when it was discovered on a layout of
/// another size: its `π_g` and graph do not fit. When the size is the same
/// but the layout's name differs, returns a warning for the caller to
/// print. Says nothing when the run recorded no layout.
pub fn check_world_graph_layout(
    dir: &Path,
    maze: Maze,
    layout: &Layout,
) -> anyhow::Result<Option<String>> {
    let Some(l) = recorded_layout(dir) else {
        return Ok(None);
    };
    if (l.width, l.height) != (layout.width, layout.height) {
        bail!(
            "the world graph {} is from maze {} ({}x{}), this run is {} ({}x{}): discover on \
             --maze {} or train on the maze of the world graph",
            dir.display(),
            l.name,
            l.width,
            l.height,
            maze.name(),
            layout.width,
            layout.height,
            maze.name()
        );
    }
    Ok((l.name != maze.name() && l.name != layout.name).then(|| {
        format!(
            "the world graph {} is from layout {}, this run is maze {} (of the same size)",
            dir.display(),
            l.name,
            maze.name()
        )
    }))
}

impl DiscoveryIdentity {
    /// The identity the discover run in `dir` recorded (`config.toml`).
    pub fn read(dir: &Path) -> anyhow::Result<DiscoveryIdentity> {
        let path = dir.join("config.toml");
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("{} is not a run identity", path.display()))
    }

    /// The discovery settings the run was started with.
    pub fn config(&self) -> &DiscoveryConfig {
        &self.discovery
    }

    /// The identity of a discovery on `layout` with `envs` environments.
    pub fn new(layout: &Layout, envs: usize, cfg: &DiscoveryConfig) -> DiscoveryIdentity {
        let mut identity = cfg.clone();
        // The budget may grow on a resumed run: not part of the digest.
        identity.max_rounds = 0;
        identity.patience = 0;
        DiscoveryIdentity {
            layout: layout.name.clone(),
            layout_size: format!("{}x{}", layout.width, layout.height),
            layout_digest: fnv1a(layout.to_text().as_bytes()),
            envs,
            config_digest: fnv1a(toml::to_string(&identity).unwrap_or_default().as_bytes()),
            discovery: cfg.clone(),
        }
    }

    /// Refuses a run directory started with another layout or settings
    /// (naming what differs), then records this identity.
    pub fn check_and_record(&self, dir: &Path) -> anyhow::Result<()> {
        let path = dir.join("config.toml");
        if let Ok(text) = std::fs::read_to_string(&path) {
            let old: DiscoveryIdentity = toml::from_str(&text)
                .with_context(|| format!("{} is not a run identity", path.display()))?;
            let refuse = |what: String| {
                anyhow::anyhow!(
                    "{} was started with {what}; use another --run directory or the same settings",
                    dir.display()
                )
            };
            if old.layout != self.layout || old.layout_size != self.layout_size {
                return Err(refuse(format!(
                    "layout {} ({}), this run uses {} ({})",
                    old.layout, old.layout_size, self.layout, self.layout_size
                )));
            }
            if old.layout_digest != self.layout_digest {
                return Err(refuse(format!(
                    "another version of layout {} (cells digest {}, now {}): the file was edited",
                    self.layout, old.layout_digest, self.layout_digest
                )));
            }
            if old.envs != self.envs {
                return Err(refuse(format!(
                    "--envs {}, this run uses {}",
                    old.envs, self.envs
                )));
            }
            if let Some(diff) = crate::discovery::config_difference(&old.discovery, &self.discovery)
            {
                return Err(refuse(diff.replace("in the checkpoint", "there")));
            }
        }
        let text = toml::to_string(self).context("cannot write the run identity as TOML")?;
        sim::atomic_file::write_atomic(&path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        Ok(())
    }
}

/// Reads a TOML discovery config (unknown keys refused).
pub fn read_discovery_config(p: &Path) -> anyhow::Result<DiscoveryConfig> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
    toml::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "{} is not a valid discovery config (TOML): {}",
            p.display(),
            e.to_string().trim_end()
        )
    })
}

/// `π_g` of a discovery run, for `layout` (its weights fit any layout of
/// the same size).
pub fn load_gcp(dir: &Path, layout: &Layout) -> anyhow::Result<GoalConditionedPolicy> {
    let cfg_path = dir.join(GCP_CONFIG_FILE);
    let cfg: GcpConfig = serde_json::from_slice(&std::fs::read(&cfg_path).with_context(|| {
        format!(
            "cannot read {} (a discover run writes it)",
            cfg_path.display()
        )
    })?)
    .with_context(|| format!("{} is not a π_g config", cfg_path.display()))?;
    let mut gcp = GoalConditionedPolicy::new(&cfg, layout, 1, Task::MultiGoal.num_actions(), 0)?;
    gcp.load(dir.join(GCP_WEIGHTS_FILE))?;
    // The maze discovery trained `π_g` on is its world graph's.
    let graph_path = dir.join(GRAPH_FILE);
    let discovered = planner::WorldGraph::load(&graph_path)
        .with_context(|| format!("cannot load the world graph {}", graph_path.display()))?;
    gcp.set_trained_on(discovered.layout());
    Ok(gcp)
}

/// The world graph over the candidate set on the task's layout. One world
/// graph per maze serves every task on it (section 4.3, "Execution"): it
/// is found on the layout's structure ([`Layout::structural`]: doors open,
/// no key), so a route through a door exists and traversal refuses it only
/// while the door is closed. `V_p` as discovered (kept as it is when it
/// was discovered on that structure; otherwise its nodes standable there,
/// re-walked), or `V_rand` of the same size with edges formed the same way
/// (random walks, then `π_g` refinement); the `extra` cells
/// ([`AgentConfig::extra_candidates`]: the task's objects, the exit) join
/// the nodes, so traversal can bring the agent to them.
pub fn world_graph_for(
    dir: &Path,
    layout: &Layout,
    candidates: Candidates,
    extra: &[u32],
    seed: u64,
    gcp: &mut GoalConditionedPolicy,
) -> anyhow::Result<planner::WorldGraph> {
    let path = dir.join(GRAPH_FILE);
    let discovered = planner::WorldGraph::load(&path)
        .with_context(|| format!("cannot load the world graph {}", path.display()))?;
    let structure = layout.structural();
    let same_structure = discovered.layout().cells == structure.cells;
    let pivotal: Vec<u32> = discovered
        .nodes()
        .iter()
        .map(|c| c.0)
        .filter(|&c| {
            planner::pivotal::is_node_object(
                structure.object(c as usize % structure.width, c as usize / structure.width),
            )
        })
        .collect();
    if candidates == Candidates::Pivotal && same_structure && extra.is_empty() {
        return Ok(discovered);
    }
    let cells: Vec<u32> = match candidates {
        Candidates::Pivotal => pivotal,
        _ => planner::pivotal::v_rand(&structure, pivotal.len(), seed)?
            .iter()
            .map(|c| c.0)
            .collect(),
    };
    let nodes = planner::pivotal::nodes_from_cells(&structure, &[&cells[..], extra].concat());
    let cfg = planner::PlannerConfig {
        candidates: planner::CandidateSet::Given,
        seed,
        task: Task::MultiGoal,
        shorten: false,
        ..planner::PlannerConfig::default()
    };
    let mut graph = planner::WorldGraph::build(&structure, &cfg, &nodes)?;
    crate::edge_refinement::refine_with_gcp(&mut graph, gcp)?;
    Ok(graph)
}

/// What the agent of a run takes from stage 1 (section 4): `π_g` and,
/// for WN over `V_rand` or `V_p`, the world graph over its candidates, from
/// the discovery run `world_graph`; `None` for an agent that needs
/// neither. An agent that needs a discovery run and has none is refused.
pub fn load_inputs(
    cfg: &AgentConfig,
    layout: &Layout,
    task: Task,
    world_graph: Option<&Path>,
    seed: u64,
) -> anyhow::Result<Option<WorldGraphInputs>> {
    let Some(dir) = world_graph else {
        if cfg.needs_discovery(task) {
            bail!(
                "{} needs --world-graph DISCOVER_RUN (its V_p and π_g); run `worldgraph discover --maze ...` first",
                cfg.name()
            );
        }
        return Ok(None);
    };
    let mut gcp = load_gcp(dir, layout)?;
    let graph = if cfg.needs_graph() {
        Some(world_graph_for(
            dir,
            layout,
            cfg.candidates,
            &cfg.extra_candidates(layout),
            seed,
            &mut gcp,
        )?)
    } else {
        None
    };
    Ok(Some(WorldGraphInputs {
        graph,
        gcp: Some(gcp),
    }))
}

/// The wide-goal candidates of `cfg` on `layout` when they are known
/// before the agent is built: `V_all` from the layout, `V_p` or `V_rand`
/// from the world graph in `inputs`; `None` for FN and A2C, and for a WN
/// over a graph not given.
pub fn known_candidates(
    cfg: &AgentConfig,
    layout: &Layout,
    inputs: Option<&WorldGraphInputs>,
) -> Option<Vec<u32>> {
    let graph = inputs.and_then(|i| i.graph.as_ref());
    (cfg.kind == AgentKind::WideNarrow && (!cfg.needs_graph() || graph.is_some()))
        .then(|| wide_goal_candidates(cfg, layout, graph))
}

/// The agent of a run: configuration, layout, and the stage 1 inputs
/// ([`load_inputs`]).
pub fn build_agent(
    cfg: &AgentConfig,
    layout: &Layout,
    task: Task,
    world_graph: Option<&Path>,
    seed: u64,
) -> anyhow::Result<Agent> {
    let inputs = load_inputs(cfg, layout, task, world_graph, seed)?;
    Ok(Agent::new(cfg, layout, task, inputs, seed)?)
}
