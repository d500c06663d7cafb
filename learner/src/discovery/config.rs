//! Every setting of the discovery loop ([`DiscoveryConfig`]) and its
//! validation. Those of the research levers, which are not the paper's
//! ([`GoalChains`], [`GoalCurriculum`],
//! [`DiscoveryConfig::loop_erase_goal_trajectories`],
//! [`DiscoveryConfig::shortest_known_paths`]), say so; what they do is in
//! `departures.rs`.

use serde::{Deserialize, Serialize};

use crate::error::LearnerError;
use crate::gcp::GcpConfig;
use crate::vae::LatentConfig;

/// Settings of the discovery loop (CPU-sized defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DiscoveryConfig {
    /// Seed of everything random in the loop.
    pub seed: u64,
    /// Most rounds (the budget).
    pub max_rounds: u32,
    /// Rounds without improvement of the reconstruction accuracy before stopping.
    pub patience: u32,
    /// Rounds before a plateau may stop the loop: `π_g` needs hundreds of
    /// updates before its goal episodes mean anything, and the accuracy
    /// plateaus early on random walks alone (`docs/implementation_details.md`,
    /// "Where stage 1 departs from the paper").
    pub min_rounds: u32,
    /// Smallest accuracy gain that counts as an improvement.
    pub min_improvement: f64,
    /// Random-walk steps per environment per round.
    pub walk_steps_per_round: u32,
    /// Length of one random walk (actions).
    pub walk_len: u32,
    /// Fraction of walks started from a pivotal state (once there are some).
    pub from_pivotal: f64,
    /// Latent-model updates per round.
    pub latent_steps_per_round: u32,
    /// Trajectories per latent-model update.
    pub latent_batch: usize,
    /// Most trajectories kept for training (the newest), split evenly
    /// between the two sources: walks (random walks and path replays) and
    /// `π_g`'s goal trajectories. Every batch draws from both halves alike
    /// (all from one while the other is empty), so neither source crowds
    /// the other out: once `π_g` succeeds it yields far more trajectories
    /// than the walks, and one first-in-first-out buffer forgot the walks.
    pub buffer: usize,
    /// `π_g` A2C iterations per round (0: random walks only).
    pub gcp_iters_per_round: u32,
    /// Fraction of visited cells that become pivotal states (paper: 0.2).
    pub pivotal_ratio: f64,
    /// How far `π_g`'s training goals lie, round by round (a lever).
    pub goal_curriculum: GoalCurriculum,
    /// Erase the loops of `π_g`'s recorded trajectories before the latent
    /// model sees them, as the walks' recorded paths are
    /// (`LoopErasedRoute`): a half-trained `π_g` reaches its goals with
    /// detours (turning back and forth, stepping into walls), and what is
    /// left is the way it found, the kind of trajectory whose actions the
    /// pivotal states should explain (section 3.1). A lever, off by
    /// default.
    pub loop_erase_goal_trajectories: bool,
    /// Make the recorded path to each cell the shortest the agent knows:
    /// at the start of every round, a breadth-first search from the start
    /// pose over every transition it has observed (pose, action → pose, from
    /// the walks and `π_g`'s trajectories: its own experience, no map is
    /// consulted). Section 3.2: "the agent can straightforwardly document
    /// and reuse the paths from its initial position to states in `V_p`";
    /// a walk's own path, even with its loops erased, wanders. The replays
    /// along these paths are training data too, and a shortest turn-and-move
    /// path across rooms is the kind of trajectory whose actions the
    /// doorways explain (section 3.1, `learner/tests/pivotal_doorways.rs`).
    /// A lever, off by default.
    pub shortest_known_paths: bool,
    /// Goal chains along the agent's known routes, the goal-directed
    /// trajectories the latent model finds pivotal states in
    /// ([`GoalChains`], a lever).
    pub goal_chains: GoalChains,
    /// The latent model.
    pub latent: LatentConfig,
    /// The goal-conditioned policy.
    pub gcp: GcpConfig,
}

impl Default for DiscoveryConfig {
    fn default() -> Self {
        DiscoveryConfig {
            seed: 0,
            max_rounds: 30,
            patience: 4,
            min_rounds: 12,
            min_improvement: 0.005,
            walk_steps_per_round: 256,
            walk_len: 24,
            from_pivotal: 0.5,
            latent_steps_per_round: 40,
            latent_batch: 64,
            buffer: 4096,
            // π_g needs hundreds of A2C updates before it reaches goals
            // (docs/implementation_details.md, "Where stage 1 departs").
            gcp_iters_per_round: 100,
            pivotal_ratio: 0.2,
            goal_curriculum: GoalCurriculum::default(),
            // The three levers of issue 12's second pass stay off: none beat
            // the loop without them (docs/implementation_details.md, "Earlier
            // passes").
            loop_erase_goal_trajectories: false,
            shortest_known_paths: false,
            goal_chains: GoalChains::default(),
            latent: LatentConfig::default(),
            gcp: GcpConfig::default(),
        }
    }
}

impl DiscoveryConfig {
    /// Checks the values once, before anything is built.
    pub fn validate(&self) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: &str| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if self.max_rounds == 0 {
            return bad("max_rounds", "must be at least 1");
        }
        if self.walk_len == 0 || self.walk_steps_per_round < self.walk_len {
            return bad(
                "walk_len",
                "must be at least 1 and at most walk_steps_per_round",
            );
        }
        if !(0.0..=1.0).contains(&self.from_pivotal) {
            return bad("from_pivotal", "must be in [0, 1]");
        }
        if !(self.pivotal_ratio > 0.0 && self.pivotal_ratio <= 1.0) {
            return bad("pivotal_ratio", "must be in (0, 1]");
        }
        if self.latent_batch == 0 || self.buffer < self.latent_batch {
            return bad("latent_batch", "must be at least 1 and at most buffer");
        }
        self.goal_curriculum.validate(self.gcp.goal_walk_len)?;
        self.goal_chains.validate()?;
        self.latent.validate()?;
        self.gcp.validate()?;
        Ok(())
    }
}

impl DiscoveryConfig {
    /// True when the loop books the transitions it observes (the known
    /// routes are used).
    pub fn records_experience(&self) -> bool {
        self.shortest_known_paths || self.goal_chains.per_round > 0
    }
}

/// Goal chains: trajectories that reach `legs` goals in turn, each along
/// a shortest route through the transitions the agent has observed, ties
/// broken at random ([`crate::experience`]). They stand for what a trained
/// `π_g` does (section 3.2), whose trajectories the latent model learns
/// from (section 3.1): at this implementation's budget `π_g` reaches
/// goals within a room only (`docs/implementation_details.md`, "Where
/// stage 1 departs from the paper"), while a trajectory whose legs cross
/// rooms is what the doorways explain. The chains join the walks and
/// `π_g`'s episodes as a third source of the training buffer, and
/// `batch_share` of every latent batch is drawn from them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalChains {
    /// Chains drawn per round (0: none, the loop of the paper's sources
    /// alone).
    pub per_round: usize,
    /// Goals reached in turn by one chain.
    pub legs: usize,
    /// Fewest actions from one goal (or the chain's start) to the next
    /// along the shortest known route.
    pub min_actions: u32,
    /// Most actions from one goal to the next.
    pub max_actions: u32,
    /// Share of every latent-model batch drawn from the chains; the rest
    /// is split evenly between the walks and `π_g`'s episodes.
    pub batch_share: f64,
}

impl Default for GoalChains {
    fn default() -> Self {
        GoalChains {
            per_round: 512,
            legs: 1,
            min_actions: 8,
            // Beyond the farthest cell of any embedded maze: goals anywhere
            // at least `min_actions` away.
            max_actions: 1000,
            batch_share: 0.75,
        }
    }
}

impl GoalChains {
    fn validate(&self) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: &str| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if self.per_round > 0 && self.legs == 0 {
            return bad("goal_chains.legs", "must be at least 1");
        }
        if self.min_actions == 0 || self.max_actions < self.min_actions {
            return bad(
                "goal_chains.min_actions",
                "must be at least 1 and at most goal_chains.max_actions",
            );
        }
        if !(0.0..1.0).contains(&self.batch_share) {
            return bad("goal_chains.batch_share", "must be in [0, 1)");
        }
        Ok(())
    }
}

/// A curriculum on the distance of `π_g`'s training goals. The paper draws
/// goals at "the end points of random walks with reasonable length"
/// (section 3.2) and leaves the length open. Near goals are what `π_g`
/// learns first, far goals are what the latent model needs: a trajectory
/// whose legs cross rooms is explained by the doorways it passes, a short
/// one by its two ends alone (section 3.1). So goals start within
/// [`crate::gcp::GcpConfig::goal_walk_len`] moves, and after each round in which `π_g`
/// reached at least `success_threshold` of its training goals the
/// distance grows by `step` moves, up to `max_moves` (`step = 0`, the
/// default, keeps it at `goal_walk_len`). The distance is part of the
/// checkpoint, so a resumed run goes on at the distance it reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalCurriculum {
    /// Moves added to the goal distance after a round that passed
    /// `success_threshold` (0: the distance stays at `goal_walk_len`).
    pub step: usize,
    /// Training success rate of a round (mean over its A2C iterations) at
    /// which the next round's goals lie `step` moves farther.
    pub success_threshold: f64,
    /// The farthest goal distance, in moves.
    pub max_moves: usize,
}

impl Default for GoalCurriculum {
    fn default() -> Self {
        GoalCurriculum {
            // Off (see `DiscoveryConfig::default`); `step = 2` turns it on.
            step: 0,
            success_threshold: 0.5,
            max_moves: 16,
        }
    }
}

impl GoalCurriculum {
    fn validate(&self, start: usize) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: String| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if !(self.success_threshold > 0.0 && self.success_threshold <= 1.0) {
            return bad(
                "goal_curriculum.success_threshold",
                format!("{} must be in (0, 1]", self.success_threshold),
            );
        }
        if self.step > 0 && self.max_moves < start {
            return bad(
                "goal_curriculum.max_moves",
                format!(
                    "{} must be at least gcp.goal_walk_len ({start})",
                    self.max_moves
                ),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curriculum_settings_are_checked() {
        let mut cfg = DiscoveryConfig::default();
        assert!(cfg.validate().is_ok());
        cfg.goal_curriculum.success_threshold = 0.0;
        assert!(cfg.validate().is_err());
        cfg.goal_curriculum.success_threshold = 0.5;
        cfg.goal_curriculum.step = 2;
        cfg.goal_curriculum.max_moves = cfg.gcp.goal_walk_len - 1;
        let err = cfg.validate().expect_err("max_moves below the start");
        assert!(
            err.to_string().contains("goal_curriculum.max_moves"),
            "{err}"
        );
        cfg.goal_curriculum.step = 0;
        assert!(cfg.validate().is_ok(), "no curriculum, no cap to check");
    }
}
