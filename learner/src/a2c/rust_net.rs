//! The whole actor-critic (encoder, LSTM core, heads) run by the own
//! kernels outside tch's autograd: the path [`GradPath::RustCore`].
//!
//! While acting, each step runs the encoder ([`RustEncoder`]), one LSTM
//! cell step and the heads ([`crate::a2c::lstm`]) on floats and keeps every
//! activation; no autograd graph is built. The update computes the loss in
//! tch over the rollout's logits and values as leaves (the same
//! [`crate::a2c::a2c_loss`] as every path), takes their gradients, and runs
//! the rest of the backward here: the heads over all `T·B` rows at once,
//! the core backward through time (one small product per step, the weight
//! and input gradients as three GEMMs over the rollout), then the encoder's
//! backward over the rollout. The gradients reach the caller's optimiser
//! through [`with_gradients`].
//!
//! **Where the core's state was reset.** The caller hands every step the
//! state to start from, after zeroing the rows whose episode (or, for the
//! Worker, whose goal) ended: tch's `reset_done` multiplies by a 0/1 mask,
//! so the gradient of a kept row flows back to the previous step and that
//! of a zeroed row does not. Here a row's state is taken to continue the
//! previous step's output exactly when it equals it bit for bit (`x · 1`
//! is `x`); any other state — zeroed, or set anew — starts a new sequence,
//! as it does in tch. The rollout's first step starts from the detached
//! state [`crate::a2c::rollout::Rollout::start`] records.
//!
//! [`GradPath::RustCore`]: crate::a2c::rollout::GradPath::RustCore

use tch::Tensor;

use super::encoder::{RustEncoder, with_gradients};
use super::input::CellInput;
use super::lstm::{Heads, LstmCell, Sequence, transposed};
use super::net::{ActorCritic, ActorCriticOutput, LstmState, Trunk};
use super::tensors::floats;

/// The network's weights in the kernels' layouts and the activations of
/// the steps taken since the last [`RustActorCritic::load`].
#[derive(Debug)]
pub struct RustActorCritic {
    encoder: RustEncoder,
    cell: LstmCell,
    heads: Heads,
    core: CoreWeights,
    /// The policy head's weight, in tch's layout and transposed.
    w_pi: Vec<f32>,
    w_pi_t: Vec<f32>,
    b_pi: Vec<f32>,
    w_v: Vec<f32>,
    b_v: f32,
    /// Rows per step (environments).
    batch: usize,
    /// Per step and row (`t·B + b`): the state it started from, its
    /// activated gates, `tanh` of its cell output, its hidden output.
    h_in: Vec<f32>,
    c_in: Vec<f32>,
    gates: Vec<f32>,
    tanh_c: Vec<f32>,
    h_out: Vec<f32>,
    /// The last step's cell output (what the next step's state is compared
    /// with).
    c_last: Vec<f32>,
    /// Whether row `t·B + b`'s state continues step `t − 1`'s output.
    continues: Vec<bool>,
    /// The logits `[T·B, A]` and values `[T·B]` of the steps.
    logits: Vec<f32>,
    values: Vec<f32>,
}

impl RustActorCritic {
    /// The network `net`, with its current weights.
    pub fn new(net: &ActorCritic) -> RustActorCritic {
        let trunk = net.trunk();
        let hidden = trunk.hidden() as usize;
        let mut own = RustActorCritic {
            encoder: RustEncoder::new(trunk),
            cell: LstmCell {
                input: hidden,
                hidden,
            },
            heads: Heads {
                hidden,
                actions: net.config().num_actions as usize,
            },
            core: CoreWeights::default(),
            w_pi: Vec::new(),
            w_pi_t: Vec::new(),
            b_pi: Vec::new(),
            w_v: Vec::new(),
            b_v: 0.0,
            batch: 0,
            h_in: Vec::new(),
            c_in: Vec::new(),
            gates: Vec::new(),
            tanh_c: Vec::new(),
            h_out: Vec::new(),
            c_last: Vec::new(),
            continues: Vec::new(),
            logits: Vec::new(),
            values: Vec::new(),
        };
        own.load(net);
        own
    }

    /// Reads the network's current weights and forgets the steps (at the
    /// start of a rollout).
    pub fn load(&mut self, net: &ActorCritic) {
        let trunk = net.trunk();
        self.encoder.load(trunk);
        self.core = CoreWeights::of(trunk, &self.cell);
        let hd = self.cell.hidden;
        let [w_pi, b_pi, w_v, b_v] = net.head_parameters().map(|t| floats(&t.detach()));
        self.w_pi_t = transposed(&w_pi, self.heads.actions, hd);
        self.w_pi = w_pi;
        self.b_pi = b_pi;
        self.w_v = w_v;
        self.b_v = b_v[0];
        self.batch = 0;
        for v in [
            &mut self.h_in,
            &mut self.c_in,
            &mut self.gates,
            &mut self.tanh_c,
            &mut self.h_out,
            &mut self.c_last,
            &mut self.logits,
            &mut self.values,
        ] {
            v.clear();
        }
        self.continues.clear();
    }

    /// Steps taken since [`Self::load`].
    pub fn steps(&self) -> usize {
        self.continues.len() / self.batch.max(1)
    }

    /// One step on the `B` observations of `input` from `state`: the
    /// logits, values and next state (tensors without a graph), every
    /// activation kept for [`Self::backward`].
    pub fn step(&mut self, input: &CellInput, state: &LstmState) -> ActorCriticOutput {
        let n = input.len();
        let hd = self.cell.hidden;
        if self.continues.is_empty() {
            self.batch = n;
        }
        assert_eq!(n, self.batch, "every step of a rollout has the same rows");
        let (h, c) = (floats(&state.h), floats(&state.c));
        let first = self.continues.is_empty();
        for b in 0..n {
            let continues = !first && {
                let prev = self.h_out.len() - n * hd + b * hd;
                let same =
                    |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
                same(&h[b * hd..][..hd], &self.h_out[prev..][..hd])
                    && same(&c[b * hd..][..hd], &self.c_last[b * hd..][..hd])
            };
            self.continues.push(continues);
        }
        let x = self.encoder.encode(input);
        let grow = |v: &mut Vec<f32>, per: usize| {
            let start = v.len();
            v.resize(start + n * per, 0.0);
            start
        };
        let s = grow(&mut self.h_in, hd);
        self.h_in[s..].copy_from_slice(&h);
        grow(&mut self.c_in, hd);
        self.c_in[s..].copy_from_slice(&c);
        let sg = grow(&mut self.gates, 4 * hd);
        grow(&mut self.tanh_c, hd);
        grow(&mut self.h_out, hd);
        self.c_last.resize(n * hd, 0.0);
        self.cell.forward(
            x,
            &h,
            &c,
            n,
            &self.core.w_ih_t,
            &self.core.w_hh_t,
            &self.core.bias,
            &mut self.gates[sg..],
            &mut self.c_last,
            &mut self.tanh_c[s..],
            &mut self.h_out[s..],
        );
        let a = self.heads.actions;
        let sl = grow(&mut self.logits, a);
        let sv = grow(&mut self.values, 1);
        self.heads.forward(
            &self.h_out[s..],
            n,
            &self.w_pi_t,
            &self.b_pi,
            &self.w_v,
            self.b_v,
            &mut self.logits[sl..],
            &mut self.values[sv..],
        );
        let (ni, hi) = (n as i64, hd as i64);
        ActorCriticOutput {
            logits: Tensor::from_slice(&self.logits[sl..]).view([ni, a as i64]),
            value: Tensor::from_slice(&self.values[sv..]),
            state: LstmState {
                h: Tensor::from_slice(&self.h_out[s..]).view([ni, hi]),
                c: Tensor::from_slice(&self.c_last).view([ni, hi]),
            },
        }
    }

    /// The logits `[T·B, A]` of the steps taken, row-major.
    pub fn logits(&self) -> &[f32] {
        &self.logits
    }

    /// The backward pass over every step since [`Self::load`], from the
    /// loss's gradients with respect to their logits `[T·B, A]` and values
    /// `[T·B]`. Returns the gradients of [`parameters`]`(net)`, in order and
    /// in tch's layouts.
    pub fn backward(&mut self, dlogits: &[f32], dvalues: &[f32]) -> Vec<Tensor> {
        let (hd, a) = (self.cell.hidden, self.heads.actions);
        let (n, rows) = (self.batch, self.continues.len());
        assert_eq!(
            dlogits.len(),
            rows * a,
            "one logit gradient per step and action"
        );
        assert_eq!(dvalues.len(), rows, "one value gradient per step");
        let (mut dw_pi, mut db_pi) = (vec![0f32; self.w_pi.len()], vec![0f32; a]);
        let (mut dw_v, mut db_v) = (vec![0f32; hd], 0f32);
        let mut dh_out = vec![0f32; rows * hd];
        self.heads.backward(
            &self.h_out,
            rows,
            &self.w_pi,
            &self.w_v,
            dlogits,
            dvalues,
            &mut dw_pi,
            &mut db_pi,
            &mut dw_v,
            &mut db_v,
            &mut dh_out,
        );
        let seq = Sequence {
            gates: &self.gates,
            c_in: &self.c_in,
            tanh_c: &self.tanh_c,
            continues: &self.continues,
        };
        let mut grads = trunk_backward(
            &mut self.encoder,
            &self.cell,
            &self.core,
            &seq,
            &self.h_in,
            n,
            &dh_out,
        );
        let hi = hd as i64;
        grads.extend([
            Tensor::from_slice(&dw_pi).view([a as i64, hi]),
            Tensor::from_slice(&db_pi),
            Tensor::from_slice(&dw_v).view([1, hi]),
            Tensor::from_slice(&[db_v]),
        ]);
        grads
    }
}

/// An LSTM core's weights as the own kernels read them: in tch's layouts
/// (the backward's) and transposed (the forward's).
#[derive(Debug, Default)]
pub(crate) struct CoreWeights {
    /// `weight_ih` `[4H, I]` and `weight_hh` `[4H, H]`.
    pub w_ih: Vec<f32>,
    pub w_hh: Vec<f32>,
    /// The same, transposed.
    pub w_ih_t: Vec<f32>,
    pub w_hh_t: Vec<f32>,
    /// `b_ih + b_hh`.
    pub bias: Vec<f32>,
}

impl CoreWeights {
    /// The current weights of `trunk`'s core, whose shape `cell` gives.
    pub(crate) fn of(trunk: &Trunk, cell: &LstmCell) -> Self {
        let [w_ih, w_hh, b_ih, b_hh] = trunk.core_parameters().map(|t| floats(&t.detach()));
        let (g4, hd) = (4 * cell.hidden, cell.hidden);
        CoreWeights {
            w_ih_t: transposed(&w_ih, g4, cell.input),
            w_hh_t: transposed(&w_hh, g4, hd),
            w_ih,
            w_hh,
            bias: b_ih.iter().zip(&b_hh).map(|(a, b)| a + b).collect(),
        }
    }
}

/// The backward pass of an encoder and LSTM core unrolled over `rows =
/// steps · n` rows (the actor-critic's rollout, the Manager's queued
/// decisions), from the loss's gradient `dh` `[rows, H]` of the core's
/// hidden states: backward through time, the weight and input gradients
/// over all rows at once, then the encoder's backward. Returns the
/// encoder's parameters' gradients, then `weight_ih`, `weight_hh`,
/// `bias_ih` and `bias_hh` (one sum, so the same for both), in tch's
/// layouts.
pub(crate) fn trunk_backward(
    encoder: &mut RustEncoder,
    cell: &LstmCell,
    core: &CoreWeights,
    seq: &Sequence<'_>,
    h_in: &[f32],
    n: usize,
    dh: &[f32],
) -> Vec<Tensor> {
    let (hd, g4, input) = (cell.hidden, 4 * cell.hidden, cell.input);
    let rows = seq.continues.len();
    let mut dz = vec![0f32; rows * g4];
    cell.backward_through_time(n, &core.w_hh, seq, dh, &mut dz);
    let (mut dw_ih, mut dw_hh) = (vec![0f32; core.w_ih.len()], vec![0f32; core.w_hh.len()]);
    let (mut dbias, mut dx) = (vec![0f32; g4], vec![0f32; rows * input]);
    cell.weight_gradients(
        &dz,
        encoder.features(),
        h_in,
        rows,
        &core.w_ih,
        &mut dw_ih,
        &mut dw_hh,
        &mut dbias,
        &mut dx,
    );
    let (g, hi, ii) = (g4 as i64, hd as i64, input as i64);
    encoder
        .backward(&dx)
        .into_iter()
        .chain([
            Tensor::from_slice(&dw_ih).view([g, ii]),
            Tensor::from_slice(&dw_hh).view([g, hi]),
            Tensor::from_slice(&dbias),
            Tensor::from_slice(&dbias),
        ])
        .collect()
}

/// The parameters [`RustActorCritic::backward`] returns gradients for, in
/// its order: the encoder's, the core's, the heads'.
pub fn parameters(net: &ActorCritic) -> Vec<Tensor> {
    let trunk = net.trunk();
    trunk
        .encoder_parameters()
        .into_iter()
        .chain(trunk.core_parameters())
        .chain(net.head_parameters())
        .collect()
}

/// The loss whose `backward` hands the gradients of [`RustActorCritic::backward`]
/// to the caller's optimiser: `loss` has the value of the A2C loss over the
/// leaves `logits` and `values`, whose gradients it takes first.
pub fn backward(
    own: &mut RustActorCritic,
    net: &ActorCritic,
    loss: &Tensor,
    logits: &Tensor,
    values: &Tensor,
) -> Tensor {
    let grads = Tensor::run_backward(&[loss], &[logits, values], false, false);
    let dense = |g: &Tensor, like: &Tensor| {
        if g.defined() {
            floats(g)
        } else {
            floats(&like.zeros_like())
        }
    };
    let (dlogits, dvalues) = (dense(&grads[0], logits), dense(&grads[1], values));
    let grads = own.backward(&dlogits, &dvalues);
    with_gradients(loss, &parameters(net), &grads)
}
