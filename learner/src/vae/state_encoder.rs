//! State features shared in shape by the prior, the posterior encoder and
//! the decoder of the latent model (Shang et al. 2019, section 3.1).
//!
//! In a fixed maze a state is the agent's pose: its cell, direction and
//! carried object (the grid itself is the same in every state, so it adds
//! nothing the cell index does not already identify). Each part gets a
//! learned embedding; the features are `relu(W·(e_cell + e_dir + e_carried) + b)`.

use tch::Tensor;
use tch::nn::{self, Module};

use super::config::LatentConfig;

/// Embeds agent poses into `state_dim` features.
#[derive(Debug)]
pub struct StateEncoder {
    cell: nn::Embedding,
    direction: nn::Embedding,
    carried: nn::Embedding,
    project: nn::Linear,
}

impl StateEncoder {
    /// Builds the embeddings under `p` (`p / "cell"`, `p / "direction"`, ...).
    pub fn new(p: &nn::Path, cfg: &LatentConfig) -> Self {
        let d = cfg.state_dim;
        let emb = Default::default();
        Self {
            cell: nn::embedding(p / "cell", cfg.num_cells, d, emb),
            direction: nn::embedding(p / "direction", cfg.num_directions, d, emb),
            carried: nn::embedding(p / "carried", cfg.num_carried, d, emb),
            project: nn::linear(p / "project", d, d, Default::default()),
        }
    }

    /// `cells`, `directions`, `carried`: int64 tensors of one shape `[...]`;
    /// returns `[..., state_dim]`.
    pub fn forward(&self, cells: &Tensor, directions: &Tensor, carried: &Tensor) -> Tensor {
        let summed = self.cell.forward(cells)
            + self.direction.forward(directions)
            + self.carried.forward(carried);
        self.project.forward(&summed).relu()
    }
}
