//! Hyperparameters of the pivotal-state latent model (Shang et al. 2019,
//! section 3.1). The paper leaves most of them to its code; the defaults
//! here are sized for a CPU and for the small and medium mazes, and the
//! Lagrangian ones follow docs/latent-model-math.md ("Lagrangian
//! relaxation").

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// All hyperparameters of [`super::LatentModel`] and its training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LatentConfig {
    // ---- state and action spaces (taken from the maze) ----
    /// Number of grid cells `W·H` (rows of the cell embedding).
    pub num_cells: i64,
    /// Facings the model tells apart in a state: 1 (the default) reads
    /// every facing as one, so a state is the agent's cell and carried
    /// object; 4 (MiniGrid's directions) adds the facing. With the facing
    /// the decoder reads every turn off the change of facing between two
    /// kept states, so the states that explain a route are the points
    /// where it turns, which lie anywhere along the line through a doorway;
    /// without it, the decoder must place the route from where its kept
    /// states are, and the doorway pins down most of a route that crosses
    /// rooms (docs/implementation_details.md, "Pivotal states").
    pub num_directions: i64,
    /// Number of carried-object kinds, 0 meaning "nothing".
    pub num_carried: i64,
    /// Number of actions (MiniGrid: 7; the MultiGoal tasks use 3 of them).
    pub num_actions: i64,

    // ---- network sizes ----
    /// Width of the state features produced by each `StateEncoder`.
    pub state_dim: i64,
    /// Width of the action embedding read by the posterior encoder.
    pub action_dim: i64,
    /// Hidden width of each direction of the bidirectional LSTMs
    /// (posterior encoder and decoder).
    pub lstm_hidden: i64,
    /// Hidden width of the prior network's MLP.
    pub prior_hidden: i64,

    // ---- objective ----
    /// `μ0 / T`: kept interior states per interior state. The paper states
    /// `μ0` "given a sequence of length `T`" (section 3.1), so the target
    /// of a trajectory grows with it: `μ0 = kept_per_step · (T − 1)` for its
    /// `T − 1` interior states. L0 targets `μ0`; the transition regulariser
    /// targets the changes `μ0` isolated kept states make, `2·μ0`, plus the
    /// two that the fixed boundary latents `z_0 = z_T = 1` always add. (A
    /// fixed count per trajectory pushed short trajectories to keep
    /// everything, and targeting `2·μ0` changes including the boundaries'
    /// pulled L0 and LT apart by one kept state.)
    pub kept_per_step: f64,
    /// Tolerance of the KL constraint, nats per trajectory: the multiplier
    /// `λ1` grows while the moving average of the KL exceeds it.
    pub kl_budget: f64,
    /// Tolerance of the L0 constraint `(E[‖Z‖₀] − μ0)² ≤ tol`.
    pub l0_tolerance: f64,
    /// Tolerance of the transition constraint `(E[#changes] − 2μ0)² ≤ tol`.
    pub transition_tolerance: f64,

    // ---- Lagrange multipliers λ1 (KL), λ2 (L0), λ3 (transitions) ----
    /// Initial value of every multiplier (notes: start small, ≈ 1e-3).
    pub lambda_init: f64,
    /// Lower clamp of the multipliers.
    pub lambda_min: f64,
    /// Upper clamp of the multipliers.
    pub lambda_max: f64,
    /// `η` of the update `λ ← clamp(λ·exp(η·c̄), λ_min, λ_max)`.
    pub lagrange_lr: f64,
    /// Decay of the moving average `c̄` of each constraint value.
    pub constraint_decay: f64,

    // ---- optimisation ----
    /// Adam learning rate of the model parameters (θ, φ, ψ).
    pub learning_rate: f64,
    /// Gradients are clipped to this global L2 norm.
    pub grad_clip_norm: f64,
}

impl Default for LatentConfig {
    fn default() -> Self {
        Self {
            // A 25×25 grid covers the small and medium mazes.
            num_cells: 25 * 25,
            num_directions: 1,
            num_carried: 8,
            num_actions: 7,
            state_dim: 32,
            action_dim: 8,
            lstm_hidden: 64,
            prior_hidden: 64,
            kept_per_step: 0.2,
            kl_budget: 1.0,
            l0_tolerance: 0.5,
            transition_tolerance: 1.0,
            lambda_init: 1e-3,
            lambda_min: 1e-4,
            lambda_max: 10.0,
            lagrange_lr: 0.05,
            constraint_decay: 0.9,
            learning_rate: 3e-3,
            grad_clip_norm: 5.0,
        }
    }
}

impl LatentConfig {
    /// The row of the direction embedding a facing reads
    /// ([`Self::num_directions`]): every facing is row 0 for a model of one
    /// direction, its own row otherwise.
    pub fn facing_index(&self, direction: u8) -> i64 {
        if self.num_directions == 1 {
            0
        } else {
            i64::from(direction)
        }
    }

    /// Checks every field once, before a model is built.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let positive_ints = [
            ("num_cells", self.num_cells),
            ("num_directions", self.num_directions),
            ("num_carried", self.num_carried),
            ("num_actions", self.num_actions),
            ("state_dim", self.state_dim),
            ("action_dim", self.action_dim),
            ("lstm_hidden", self.lstm_hidden),
            ("prior_hidden", self.prior_hidden),
        ];
        for (field, value) in positive_ints {
            if value < 1 {
                return Err(ConfigError::new(field, format!("must be ≥ 1, got {value}")));
            }
        }
        let non_negative = [
            ("kept_per_step", self.kept_per_step),
            ("kl_budget", self.kl_budget),
            ("l0_tolerance", self.l0_tolerance),
            ("transition_tolerance", self.transition_tolerance),
            ("lagrange_lr", self.lagrange_lr),
        ];
        for (field, value) in non_negative {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ConfigError::new(
                    field,
                    format!("must be finite and ≥ 0, got {value}"),
                ));
            }
        }
        let positive = [
            ("lambda_min", self.lambda_min),
            ("learning_rate", self.learning_rate),
            ("grad_clip_norm", self.grad_clip_norm),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ConfigError::new(
                    field,
                    format!("must be finite and > 0, got {value}"),
                ));
            }
        }
        if !(self.lambda_max.is_finite() && self.lambda_max >= self.lambda_min) {
            return Err(ConfigError::new(
                "lambda_max",
                format!(
                    "must be finite and ≥ lambda_min = {}, got {}",
                    self.lambda_min, self.lambda_max
                ),
            ));
        }
        if !(self.lambda_min..=self.lambda_max).contains(&self.lambda_init) {
            return Err(ConfigError::new(
                "lambda_init",
                format!(
                    "must lie in [lambda_min, lambda_max], got {}",
                    self.lambda_init
                ),
            ));
        }
        if !(0.0..1.0).contains(&self.constraint_decay) {
            return Err(ConfigError::new(
                "constraint_decay",
                format!("must lie in [0, 1), got {}", self.constraint_decay),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_round_trips_through_json() {
        let cfg = LatentConfig::default();
        cfg.validate().expect("default config is valid");
        let json = serde_json::to_string(&cfg).expect("serialises");
        let back: LatentConfig = serde_json::from_str(&json).expect("deserialises");
        assert_eq!(cfg, back);
    }

    #[test]
    fn missing_fields_take_defaults_and_unknown_fields_are_rejected() {
        let cfg: LatentConfig =
            serde_json::from_str(r#"{"num_cells": 169}"#).expect("partial config");
        assert_eq!(cfg.num_cells, 169);
        assert_eq!(cfg.lstm_hidden, LatentConfig::default().lstm_hidden);
        assert!(serde_json::from_str::<LatentConfig>(r#"{"num_cell": 169}"#).is_err());
    }

    #[test]
    fn validate_names_the_bad_field() {
        let bad = [
            LatentConfig {
                num_cells: 0,
                ..Default::default()
            },
            LatentConfig {
                kept_per_step: -1.0,
                ..Default::default()
            },
            LatentConfig {
                lambda_init: 100.0,
                ..Default::default()
            },
            LatentConfig {
                constraint_decay: 1.0,
                ..Default::default()
            },
            LatentConfig {
                learning_rate: f64::NAN,
                ..Default::default()
            },
        ];
        let fields = [
            "num_cells",
            "kept_per_step",
            "lambda_init",
            "constraint_decay",
            "learning_rate",
        ];
        for (cfg, field) in bad.iter().zip(fields) {
            let err = cfg.validate().expect_err("invalid config");
            assert_eq!(err.field, field);
        }
    }
}
