//! The settings of the discovery loop ([`DiscoveryConfig`]) and their
//! validation. The levers' own settings ([`GoalChains`],
//! [`GoalCurriculum`]) live with what they do, in `levers.rs`.

use serde::{Deserialize, Serialize};

use super::levers::{GoalChains, GoalCurriculum};
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
    /// How far `π_g`'s training goals lie, round by round.
    pub goal_curriculum: GoalCurriculum,
    /// Erase the loops of `π_g`'s recorded trajectories before the latent
    /// model sees them, as the walks' recorded paths are
    /// (`LoopErasedRoute`): a half-trained `π_g` reaches its goals with
    /// detours (turning back and forth, stepping into walls), and what is
    /// left is the way it found, the kind of trajectory whose actions the
    /// pivotal states should explain (section 3.1). Off by default.
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
    /// Off by default.
    pub shortest_known_paths: bool,
    /// Goal chains along the agent's known routes, the goal-directed
    /// trajectories the latent model finds pivotal states in
    /// ([`GoalChains`]).
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
