//! Which way an every-step learner's update gets its gradients: what both
//! the rollout (`rollout`, which fills its storage accordingly) and the
//! FLOP count of a step (`net::flops_per_env_step`) are told. On its own
//! so that neither of the two modules needs the other for it.

/// How the update gets its gradients (the `rollout` module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GradPath {
    /// Act without gradient, recompute the rollout in one batch.
    Recompute,
    /// Keep the autograd graph of every step; gather-and-sum first layer.
    #[default]
    PerStep,
    /// The plain implementation: the autograd graph of every step, the
    /// dense first convolution over one-hot planes.
    Plain,
}
