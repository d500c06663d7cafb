//! The bidirectional LSTM of the posterior encoder and of the decoder
//! (Shang et al. 2019, section 3.1, Figure 2), written so that padding never
//! leaks into a trajectory.
//!
//! libtorch's bidirectional LSTM runs its backward direction from the padded
//! end, so a short trajectory would start that direction after a stretch of
//! padding. Here the backward LSTM reads each trajectory reversed *within its
//! own length* ([`TrajectoryBatch::reverse_in_time`]), and its outputs are
//! reversed back.
//!
//! Both directions step `lstm_cell` through time instead of calling
//! libtorch's fused `lstm` (which `tch::nn::LSTM` uses even for one step): on
//! CPU that op dispatches to oneDNN, whose LSTM kernel crashed (SIGSEGV in
//! `dnnl_memory_destroy`, libtorch 2.13) on our `[L ≈ 20, B = 32, 40]`
//! training inputs. At these sizes the loop costs little.

use tch::Tensor;
use tch::nn;

use super::batch::TrajectoryBatch;

/// One LSTM layer, PyTorch's gate layout and initialisation
/// (`U(−1/√H, 1/√H)` for every weight and bias).
#[derive(Debug)]
pub struct LstmLayer {
    weight_ih: Tensor,
    weight_hh: Tensor,
    bias_ih: Tensor,
    bias_hh: Tensor,
    hidden: i64,
}

impl LstmLayer {
    /// `in_dim` inputs and `hidden` units; weights under `p`.
    pub fn new(p: &nn::Path, in_dim: i64, hidden: i64) -> Self {
        let bound = 1.0 / (hidden as f64).sqrt();
        let init = nn::Init::Uniform {
            lo: -bound,
            up: bound,
        };
        Self {
            weight_ih: p.var("weight_ih", &[4 * hidden, in_dim], init),
            weight_hh: p.var("weight_hh", &[4 * hidden, hidden], init),
            bias_ih: p.var("bias_ih", &[4 * hidden], init),
            bias_hh: p.var("bias_hh", &[4 * hidden], init),
            hidden,
        }
    }

    /// Runs over `x` (`[L, B, in]`) from a zero state; returns the hidden
    /// states `[L, B, hidden]`.
    pub fn unroll(&self, x: &Tensor) -> Tensor {
        let batch = x.size()[1];
        let zeros = x.new_zeros([batch, self.hidden], (x.kind(), x.device()));
        let (mut h, mut c) = (zeros.shallow_clone(), zeros);
        let mut outputs = Vec::with_capacity(x.size()[0] as usize);
        for t in 0..x.size()[0] {
            (h, c) = x.get(t).lstm_cell(
                &[&h, &c],
                &self.weight_ih,
                &self.weight_hh,
                Some(&self.bias_ih),
                Some(&self.bias_hh),
            );
            outputs.push(h.shallow_clone());
        }
        Tensor::stack(&outputs, 0)
    }
}

/// Two LSTM layers, one per time direction.
#[derive(Debug)]
pub struct BiLstm {
    forward: LstmLayer,
    backward: LstmLayer,
}

impl BiLstm {
    /// `in_dim` inputs, `hidden` units per direction; weights under
    /// `p / "forward"` and `p / "backward"`.
    pub fn new(p: &nn::Path, in_dim: i64, hidden: i64) -> Self {
        Self {
            forward: LstmLayer::new(&(p / "forward"), in_dim, hidden),
            backward: LstmLayer::new(&(p / "backward"), in_dim, hidden),
        }
    }

    /// `x`: `[L, B, in_dim]` (time-major, padded as `batch`); returns
    /// `[L, B, 2·hidden]`, the forward and backward hidden states at each
    /// step. Outputs on padding are meaningless and must be masked.
    pub fn seq(&self, x: &Tensor, batch: &TrajectoryBatch) -> Tensor {
        let ahead = self.forward.unroll(x);
        let behind = batch.reverse_in_time(&self.backward.unroll(&batch.reverse_in_time(x)));
        Tensor::cat(&[ahead, behind], -1)
    }
}
