//! Which way an every-step learner's update gets its gradients: what the
//! rollout (`rollout`, which fills its storage accordingly), the Manager and
//! the FLOP count of a step (`net::flops_per_env_step`) are told. On its
//! own so that none of them needs another for it.
//!
//! There is one production path, [`GradPath::RustCore`]; [`GradPath::Tch`]
//! is the reference the tests hold it equal to (loss and every gradient to
//! 1e-5) and the baseline `worldgraph bench learner` measures it against.
//! The path is a setting of the learner's configuration (`agent.grad_path`,
//! `gcp.grad_path`), written to `config.toml` only where it is not the
//! production one. Summaries made on the paths this version no longer has
//! (`rust-encoder`, `per-step`, `plain`, `recompute`) reproduce on the commit
//! they record.

use serde::{Deserialize, Serialize};

/// How the update gets its gradients (the `rollout` module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GradPath {
    /// The reference: tch's autograd graph of every step (first layer by
    /// gather-and-sum), one backward over the rollout.
    Tch,
    /// The whole network (encoder, LSTM core, heads) in the project's own
    /// kernels, no autograd graph while acting; tch computes the loss over
    /// the rollout's logits and values, the own kernels the rest of the
    /// backward, through time. The production path (measured fastest,
    /// `worldgraph bench learner`).
    #[default]
    RustCore,
}

impl GradPath {
    /// The path named `name` (`tch`, `rust-core`).
    pub fn from_name(name: &str) -> Option<GradPath> {
        Some(match name {
            "tch" => GradPath::Tch,
            "rust-core" => GradPath::RustCore,
            _ => return None,
        })
    }

    /// Its name (as [`Self::from_name`] reads it, and as summaries record
    /// it).
    pub fn name(self) -> &'static str {
        match self {
            GradPath::Tch => "tch",
            GradPath::RustCore => "rust-core",
        }
    }

    /// True for the production path (a configuration leaves it unwritten,
    /// so configurations written before the setting existed read the same).
    pub fn is_production(&self) -> bool {
        *self == GradPath::RustCore
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_is_read_by_name_and_the_retired_ones_are_refused() {
        for p in [GradPath::Tch, GradPath::RustCore] {
            assert_eq!(GradPath::from_name(p.name()), Some(p));
        }
        assert_eq!(GradPath::default(), GradPath::RustCore);
        for retired in ["rust-encoder", "per-step", "plain", "recompute", ""] {
            assert_eq!(GradPath::from_name(retired), None, "{retired}");
        }
    }
}
