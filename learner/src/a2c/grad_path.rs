//! Which way an every-step learner's update gets its gradients: what both
//! the rollout (`rollout`, which fills its storage accordingly) and the
//! FLOP count of a step (`net::flops_per_env_step`) are told. On its own
//! so that neither of the two modules needs the other for it.

/// How the update gets its gradients (the `rollout` module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GradPath {
    /// Act without gradient, recompute the rollout in one batch.
    Recompute,
    /// Keep the autograd graph of every step; gather-and-sum first layer.
    PerStep,
    /// The plain implementation: the autograd graph of every step, the
    /// dense first convolution over one-hot planes.
    Plain,
    /// The encoder in the own kernels, its features a leaf of every step's
    /// graph (the core and heads), its backward once over the rollout.
    RustEncoder,
    /// The whole network (encoder, LSTM core, heads) in the own kernels,
    /// no autograd graph while acting; tch computes the loss over the
    /// rollout's logits and values, the own kernels the rest of the
    /// backward, through time.
    RustCore,
}

impl GradPath {
    /// The path named `name` (`recompute`, `per-step`, `plain`,
    /// `rust-encoder`, `rust-core`).
    pub fn from_name(name: &str) -> Option<GradPath> {
        Some(match name {
            "recompute" => GradPath::Recompute,
            "per-step" => GradPath::PerStep,
            "plain" => GradPath::Plain,
            "rust-encoder" => GradPath::RustEncoder,
            "rust-core" => GradPath::RustCore,
            _ => return None,
        })
    }

    /// Its name (as [`Self::from_name`] reads it).
    pub fn name(self) -> &'static str {
        match self {
            GradPath::Recompute => "recompute",
            GradPath::PerStep => "per-step",
            GradPath::Plain => "plain",
            GradPath::RustEncoder => "rust-encoder",
            GradPath::RustCore => "rust-core",
        }
    }
}

impl Default for GradPath {
    /// [`GradPath::RustCore`] (measured fastest on the A2C baseline and
    /// the Wide-then-Narrow Worker, `worldgraph bench learner`), or the
    /// path `WORLDGRAPH_GRAD_PATH` names (read once per process).
    fn default() -> GradPath {
        static PATH: std::sync::OnceLock<GradPath> = std::sync::OnceLock::new();
        *PATH.get_or_init(|| {
            std::env::var("WORLDGRAPH_GRAD_PATH")
                .ok()
                .and_then(|v| GradPath::from_name(&v))
                .unwrap_or(GradPath::RustCore)
        })
    }
}
