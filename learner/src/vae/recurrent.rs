//! The bidirectional LSTM of the posterior encoder and of the decoder
//! (Shang et al. 2019, section 3.1, Figure 2), written so that padding never
//! leaks into a trajectory.
//!
//! libtorch's bidirectional LSTM runs its backward direction from the padded
//! end, so a short trajectory would start that direction after a stretch of
//! padding. Here the backward LSTM reads each trajectory reversed *within its
//! own length* ([`TrajectoryBatch::reverse_in_time`]), and its outputs are
//! reversed back.

use tch::nn::{self, RNN};
use tch::Tensor;

use super::batch::TrajectoryBatch;

/// Two unidirectional LSTMs, one per time direction.
#[derive(Debug)]
pub struct BiLstm {
    forward: nn::LSTM,
    backward: nn::LSTM,
}

impl BiLstm {
    /// `in_dim` inputs, `hidden` units per direction; weights under
    /// `p / "forward"` and `p / "backward"`.
    pub fn new(p: &nn::Path, in_dim: i64, hidden: i64) -> Self {
        let cfg = nn::RNNConfig { batch_first: false, ..Default::default() };
        Self {
            forward: nn::lstm(p / "forward", in_dim, hidden, cfg),
            backward: nn::lstm(p / "backward", in_dim, hidden, cfg),
        }
    }

    /// `x`: `[L, B, in_dim]` (time-major, padded as `batch`); returns
    /// `[L, B, 2·hidden]`, the forward and backward hidden states at each
    /// step. Outputs on padding are meaningless and must be masked.
    pub fn seq(&self, x: &Tensor, batch: &TrajectoryBatch) -> Tensor {
        let (ahead, _) = self.forward.seq(x);
        let (behind_reversed, _) = self.backward.seq(&batch.reverse_in_time(x));
        let behind = batch.reverse_in_time(&behind_reversed);
        Tensor::cat(&[ahead, behind], -1)
    }
}
