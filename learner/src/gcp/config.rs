//! The settings of `π_g` ([`GcpConfig`]) and their validation.
//!
//! The A2C hyperparameters (`gamma` … `grad_clip_norm`) are fields of
//! their own here, where a Manager's or Worker's are a nested
//! [`A2cConfig`] table: discovery runs' `config.toml` files (and the
//! digest of the settings they hold) have them directly in
//! `[discovery.gcp]`, so they stay there; [`GcpConfig::a2c`] gathers them.

use serde::{Deserialize, Serialize};

use crate::a2c::A2cConfig;
use crate::a2c::net::ActorCriticConfig;
use crate::a2c::rollout::GradPath;
use crate::error::ConfigError;

/// Settings of `π_g`. The paper gives no values for `π_g` beyond "A2C" and
/// the step penalty of its tasks (appendix, "every action ... receives a
/// negative reward penalty −0.01"); the defaults are CPU-sized A2C values.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct GcpConfig {
    /// Steps per environment in one rollout, `T` (one update per rollout).
    pub rollout_len: usize,
    /// Moves of the random walk whose end point is the goal.
    pub goal_walk_len: usize,
    /// The goal's time limit in steps per walk move (see [`Self::goal_time_limit`]).
    pub goal_time_factor: usize,
    /// Discount `γ`.
    pub gamma: f64,
    /// GAE `λ`.
    pub gae_lambda: f64,
    /// Weight of the entropy bonus.
    pub entropy_coef: f64,
    /// Weight of the value loss.
    pub value_coef: f64,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Gradients are rescaled to at most this global L2 norm.
    pub grad_clip_norm: f64,
    /// Reward for standing on the goal.
    pub goal_reward: f32,
    /// Reward of every step (the paper's task penalty).
    pub step_penalty: f32,
    /// Weight of the curiosity bonus (the decoder's action reconstruction
    /// error, in nats, capped at [`super::CURIOSITY_CAP_NATS`]). Keep
    /// `curiosity_coef · CURIOSITY_CAP_NATS` below `|step_penalty|`: every
    /// step then still costs, so curiosity steers *which way* `π_g` goes,
    /// never *whether* it goes to its goal (a larger coefficient made a
    /// trained `π_g` wander: `docs/implementation_details.md`, "Where stage
    /// 1 departs from the paper").
    pub curiosity_coef: f64,
    /// Record for the latent model the goal episodes `π_g` missed as well
    /// (a chain's last leg when it timed out or the environment's episode
    /// ended; the default). Off: a chain is recorded up to its last reached
    /// goal, so `π_g`'s trajectories are navigation, not wandering (see
    /// the goal episodes' `GoalBook`).
    pub record_missed_legs: bool,
    /// Output channels of the encoder's two convolutions.
    pub conv_channels: [i64; 2],
    /// Width of the encoder's output and of the LSTM core.
    pub hidden: i64,
    /// How `π_g`'s update gets its gradients: `"rust-core"` (production,
    /// the default; not written to `config.toml`) or `"tch"` (the reference
    /// the tests hold it equal to).
    #[serde(skip_serializing_if = "GradPath::is_production")]
    pub grad_path: GradPath,
}

impl Default for GcpConfig {
    fn default() -> Self {
        GcpConfig {
            rollout_len: 16,
            goal_walk_len: 6,
            goal_time_factor: 4,
            gamma: 0.95,
            gae_lambda: 0.95,
            entropy_coef: 0.01,
            value_coef: 0.5,
            learning_rate: 1e-3,
            grad_clip_norm: 0.5,
            goal_reward: 1.0,
            step_penalty: -0.01,
            curiosity_coef: 0.004,
            // Recording only up to the last reached goal did not make `V_p`
            // better (docs/implementation_details.md, "Earlier passes").
            record_missed_legs: true,
            conv_channels: [16, 32],
            hidden: 128,
            grad_path: GradPath::RustCore,
        }
    }
}

impl GcpConfig {
    /// Steps a goal drawn by a walk of `walk_len` moves may take before it
    /// counts as failed: `goal_time_factor · walk_len`.
    pub fn goal_time_limit(&self, walk_len: usize) -> u32 {
        (self.goal_time_factor * walk_len.max(1)).min(u32::MAX as usize) as u32
    }

    /// The A2C hyperparameters of `π_g`'s update.
    pub fn a2c(&self) -> A2cConfig {
        A2cConfig {
            gamma: self.gamma,
            gae_lambda: self.gae_lambda,
            entropy_coef: self.entropy_coef,
            value_coef: self.value_coef,
            learning_rate: self.learning_rate,
            grad_clip_norm: self.grad_clip_norm,
        }
    }

    /// The actor-critic of `π_g`: goal channel on, `num_actions` outputs.
    pub fn network(&self, num_actions: usize) -> ActorCriticConfig {
        ActorCriticConfig {
            conv_channels: self.conv_channels,
            hidden: self.hidden,
            num_actions: num_actions as i64,
            goal_planes: 1,
        }
    }

    /// Checks every field's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.rollout_len == 0 {
            return Err(ConfigError::new("rollout_len", "must be at least 1"));
        }
        if self.goal_walk_len == 0 {
            return Err(ConfigError::new("goal_walk_len", "must be at least 1"));
        }
        if self.goal_time_factor == 0 {
            return Err(ConfigError::new("goal_time_factor", "must be at least 1"));
        }
        self.a2c().validate("")?;
        if !(self.curiosity_coef >= 0.0 && self.curiosity_coef.is_finite()) {
            return Err(ConfigError::new(
                "curiosity_coef",
                format!("{} must be finite and ≥ 0", self.curiosity_coef),
            ));
        }
        if !self.goal_reward.is_finite() || !self.step_penalty.is_finite() {
            return Err(ConfigError::new(
                "goal_reward",
                "goal_reward and step_penalty must be finite",
            ));
        }
        if self.conv_channels.iter().any(|&c| c < 1) {
            return Err(ConfigError::new(
                "conv_channels",
                format!("{:?} must be ≥ 1", self.conv_channels),
            ));
        }
        if self.hidden < 1 {
            return Err(ConfigError::new(
                "hidden",
                format!("{} must be ≥ 1", self.hidden),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid_and_rejects_unknown_fields() {
        let cfg = GcpConfig::default();
        assert_eq!(cfg.validate(), Ok(()));
        assert_eq!(cfg.goal_time_limit(6), 24);
        let parsed: GcpConfig =
            serde_json::from_str(r#"{"goal_walk_len": 3}"#).expect("partial config parses");
        assert_eq!(
            parsed,
            GcpConfig {
                goal_walk_len: 3,
                ..GcpConfig::default()
            }
        );
        assert!(serde_json::from_str::<GcpConfig>(r#"{"goal_walk": 3}"#).is_err());
        for bad in [
            GcpConfig {
                rollout_len: 0,
                ..GcpConfig::default()
            },
            GcpConfig {
                gamma: 1.5,
                ..GcpConfig::default()
            },
            GcpConfig {
                learning_rate: 0.0,
                ..GcpConfig::default()
            },
            GcpConfig {
                curiosity_coef: -1.0,
                ..GcpConfig::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }
}
