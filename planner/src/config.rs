//! Settings of world-graph construction (Shang et al. 2019,
//! arXiv:1907.00664, section 3.3 "Edge Connections"; the paper gives no
//! walk counts or lengths, so the defaults are ours, chosen so that every
//! edge of the embedded mazes is found in well under a second).

use serde::{Deserialize, Serialize};
use sim::Task;

use crate::error::PlannerError;

/// Most nodes a graph may have: the wire format's limit (one per cell of
/// the largest grid); ids are `u16`, with `u16::MAX` reserved for "no pivot".
pub const MAX_NODES: usize = shm_schemas::MAX_PIVOTS;
const _: () = assert!(MAX_NODES < shm_schemas::NO_PIVOT as usize);

/// Most walk steps from one node (`walks_per_node × walk_len`).
pub const MAX_STEPS_PER_NODE: u64 = 1 << 31;

/// Where the graph's nodes come from (section 4, "Wide-then-Narrow":
/// `V_all`, `V_rand` or `V_p`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum CandidateSet {
    /// `V_rand`: `k` distinct cells drawn uniformly (seeded by
    /// [`PlannerConfig::seed`]) from the cells an agent can stand on.
    Random {
        /// Number of nodes.
        k: usize,
    },
    /// `V_all`: every cell an agent can stand on.
    All,
    /// A list read from a file (see [`crate::pivotal::parse_node_list`]).
    File {
        /// The file.
        path: String,
    },
    /// Cells handed over by the caller, e.g. the pivotal states `V_p`
    /// chosen by the learner by [`crate::pivotal::top_ratio`].
    Given,
}

/// How edges are found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EdgeSearch {
    /// The paper's method: random walks from every node
    /// ([`crate::edges::discover_edges`]).
    #[default]
    RandomWalks,
    /// Every edge random walks could ever find, by a search over states
    /// ([`crate::edges::exhaustive_edges_from`]): the limit of unboundedly
    /// many walks. Denser than the walks' graph (in an open room every pair
    /// of nodes is joined by some path around the others, though walks
    /// nearly always meet the nearest node first); for sparse node sets in
    /// large mazes where walks of a practical length miss long edges, and
    /// for the paper's "all pre-requisites granted" comparison of `V_rand`
    /// (section 4, footnote on `V_rand`).
    Exhaustive,
}

/// Settings of world-graph construction. `#[serde(default)]`: a partial
/// JSON object fills the rest from [`PlannerConfig::default`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlannerConfig {
    /// Where the nodes come from.
    pub candidates: CandidateSet,
    /// Seed of `V_rand` and of the random walks. Same seed ⇒ same graph,
    /// whatever the thread count.
    pub seed: u64,
    /// Random walks started from each node (split evenly over the four
    /// facings, the first `walks_per_node % 4` facings getting one more).
    pub walks_per_node: u32,
    /// Most actions per random walk; a walk also stops at the first node
    /// it reaches or when its episode ends (exit, lava).
    pub walk_len: u32,
    /// Random walks (the paper) or the exhaustive search.
    pub edge_search: EdgeSearch,
    /// Shorten every discovered edge with an exact breadth-first search
    /// that does not touch a third node ([`crate::edges::shorten_edge`]),
    /// where no learned policy refines them (the paper refines with `π_g`,
    /// as world graph discovery does).
    pub shorten: bool,
    /// The task whose rules the walks follow (balls are collected by
    /// stepping on them in the MultiGoal tasks and block the way in
    /// Door-Key). MultiGoal-Stochastic walks as MultiGoal: the graph is of
    /// the static maze, its moving lava is left to `π_g` (section 4.3, "Execution").
    pub task: Task,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            candidates: CandidateSet::Random { k: 32 },
            seed: 0,
            walks_per_node: 512,
            walk_len: 512,
            edge_search: EdgeSearch::RandomWalks,
            shorten: true,
            task: Task::MultiGoal,
        }
    }
}

impl PlannerConfig {
    /// Checks every value once, before anything is built.
    pub fn validate(&self) -> Result<(), PlannerError> {
        let bad = |field, message: String| Err(PlannerError::Config { field, message });
        if self.walks_per_node == 0 {
            return bad("walks_per_node", "must be at least 1".into());
        }
        if self.walk_len == 0 {
            return bad("walk_len", "must be at least 1".into());
        }
        // One simulator runs a node's walks; its step counter is a u32.
        if u64::from(self.walks_per_node) * u64::from(self.walk_len) > MAX_STEPS_PER_NODE {
            return bad(
                "walks_per_node",
                format!(
                    "{} walks of {} actions exceed {MAX_STEPS_PER_NODE} steps per node",
                    self.walks_per_node, self.walk_len
                ),
            );
        }
        match &self.candidates {
            CandidateSet::Random { k } if *k == 0 || *k > MAX_NODES => bad(
                "candidates.random.k",
                format!("{k} is not in 1..={MAX_NODES}"),
            ),
            CandidateSet::File { path } if path.is_empty() => {
                bad("candidates.file.path", "is empty".into())
            }
            _ => Ok(()),
        }
    }

    /// The task the walks actually follow (see [`PlannerConfig::task`]).
    pub fn walk_task(&self) -> Task {
        match self.task {
            Task::MultiGoalStochastic => Task::MultiGoal,
            t => t,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_values_name_their_field() {
        PlannerConfig::default()
            .validate()
            .expect("defaults are valid");
        let c = PlannerConfig {
            walk_len: 0,
            ..PlannerConfig::default()
        };
        let e = c.validate().expect_err("walk_len 0").to_string();
        assert!(e.contains("walk_len"), "{e}");
        let c = PlannerConfig {
            candidates: CandidateSet::Random { k: 0 },
            ..PlannerConfig::default()
        };
        assert!(
            c.validate()
                .expect_err("k 0")
                .to_string()
                .contains("candidates.random.k")
        );
        let c = PlannerConfig {
            walks_per_node: 1 << 20,
            walk_len: 1 << 12,
            ..PlannerConfig::default()
        };
        assert!(
            c.validate()
                .expect_err("too many steps")
                .to_string()
                .contains("walks_per_node")
        );
    }

    #[test]
    fn partial_json_fills_defaults_and_unknown_fields_are_refused() {
        let c: PlannerConfig =
            serde_json::from_str(r#"{"seed": 7, "candidates": "all"}"#).expect("parses");
        assert_eq!(
            (c.seed, c.candidates, c.walk_len),
            (7, CandidateSet::All, PlannerConfig::default().walk_len)
        );
        assert!(serde_json::from_str::<PlannerConfig>(r#"{"walks": 3}"#).is_err());
        let c: PlannerConfig =
            serde_json::from_str(r#"{"candidates": {"random": {"k": 5}}}"#).expect("parses");
        assert_eq!(c.candidates, CandidateSet::Random { k: 5 });
    }
}
