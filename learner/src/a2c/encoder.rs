//! The trunk's encoder run by the own kernels ([`crate::a2c::kernels`]),
//! the first part of the production gradient path (`rust-core`,
//! [`crate::a2c::rust_net`]).
//!
//! While acting, each step's observations go through the first
//! convolution, the stride-2 convolution and the linear layer here. Every
//! activation is kept: the weights do not change within a rollout (the
//! update comes after it), so they are exactly those the update's backward
//! needs, and nothing is recomputed. The update runs the encoder's backward
//! over all `T·B` observations at once (three large GEMMs per layer instead
//! of `T` small ones); [`with_gradients`] hands gradients computed outside
//! tch's autograd to the caller's optimiser.

use tch::{Kind, Tensor};

use super::input::CellInput;
use super::kernels::{DenseRelu, FirstConv, StridedConv};
use super::net::Trunk;
use super::tensors::floats;

/// The encoder's weights in the kernels' layouts, and the activations of
/// the observations encoded since the last [`RustEncoder::load`].
#[derive(Debug)]
pub struct RustEncoder {
    first: FirstConv,
    conv: StridedConv,
    fc: DenseRelu,
    /// The first convolution's table `[C·9, c1]` and bias.
    table: Vec<f32>,
    b1: Vec<f32>,
    /// The second convolution's GEMM weight `[9·c1, c2]` and bias.
    w2: Vec<f32>,
    b2: Vec<f32>,
    /// The linear layer's weight `[hidden, h'·w'·c2]`, its columns in the
    /// channels-last order of the second convolution's output (tch
    /// flattens `[c2, h', w']`), and bias.
    wf: Vec<f32>,
    /// `wf` transposed (the forward's).
    wf_t: Vec<f32>,
    bf: Vec<f32>,
    /// Column `k` of `wf` is column `fc_columns[k]` of tch's weight.
    fc_columns: Vec<usize>,
    /// The observations encoded, and their activations after each layer.
    inputs: CellInput,
    y1: Vec<f32>,
    y2: Vec<f32>,
    features: Vec<f32>,
    scratch: Vec<f32>,
}

impl RustEncoder {
    /// The encoder of `trunk`, with its current weights.
    pub fn new(trunk: &Trunk) -> RustEncoder {
        let (width, height) = trunk.grid();
        let [c1, c2] = trunk.conv_channels().map(|c| c as usize);
        let first = FirstConv {
            width,
            height,
            channels: trunk.in_channels() as usize,
            out: c1,
        };
        let conv = StridedConv {
            height,
            width,
            cin: c1,
            cout: c2,
        };
        let fc = DenseRelu {
            inputs: conv.out_len(),
            outputs: trunk.hidden() as usize,
        };
        let (ho, wo) = conv.out_hw();
        // Own column (y, x, c) ← tch column (c, y, x).
        let mut fc_columns = vec![0; fc.inputs];
        for y in 0..ho {
            for x in 0..wo {
                for c in 0..c2 {
                    fc_columns[(y * wo + x) * c2 + c] = (c * ho + y) * wo + x;
                }
            }
        }
        let mut enc = RustEncoder {
            first,
            conv,
            fc,
            table: Vec::new(),
            b1: Vec::new(),
            w2: Vec::new(),
            b2: Vec::new(),
            wf: Vec::new(),
            wf_t: Vec::new(),
            bf: Vec::new(),
            fc_columns,
            inputs: CellInput::new(
                width,
                height,
                trunk.in_channels() as usize - super::input::BASE_CHANNELS,
            ),
            y1: Vec::new(),
            y2: Vec::new(),
            features: Vec::new(),
            scratch: Vec::new(),
        };
        enc.load(trunk);
        enc
    }

    /// Reads the trunk's current weights and forgets the activations (at
    /// the start of a rollout).
    pub fn load(&mut self, trunk: &Trunk) {
        let [w1, b1, w2, b2, wf, bf] = trunk.encoder_parameters().map(|t| floats(&t.detach()));
        self.table = self.first.table(&w1);
        self.b1 = b1;
        self.w2 = self.conv.gemm_weight(&w2);
        self.b2 = b2;
        let (inputs, hidden) = (self.fc.inputs, self.fc.outputs);
        self.wf.resize(wf.len(), 0.0);
        for o in 0..hidden {
            let (own, torch) = (
                &mut self.wf[o * inputs..][..inputs],
                &wf[o * inputs..][..inputs],
            );
            for (dst, &src) in own.iter_mut().zip(&self.fc_columns) {
                *dst = torch[src];
            }
        }
        self.wf_t = super::gemm::transposed(&self.wf, hidden, inputs);
        self.bf = bf;
        self.clear();
    }

    /// Forgets the activations, keeps the weights (an encoder that only
    /// acts, such as the Manager's between its updates).
    pub fn clear(&mut self) {
        self.inputs.clear();
        self.y1.clear();
        self.y2.clear();
        self.features.clear();
    }

    /// Observations encoded since [`Self::load`].
    pub fn len(&self) -> usize {
        self.inputs.len()
    }

    /// True when nothing was encoded since [`Self::load`].
    pub fn is_empty(&self) -> bool {
        self.inputs.is_empty()
    }

    /// The features `[n, hidden]` of the `n` observations of `input`
    /// (no autograd graph), their activations kept for [`Self::backward`].
    pub fn forward(&mut self, input: &CellInput) -> Tensor {
        let n = input.len() as i64;
        Tensor::from_slice(self.encode(input)).view([n, self.fc.outputs as i64])
    }

    /// [`Self::forward`] as floats: the features `[n, hidden]` of the `n`
    /// observations of `input`, row-major.
    pub fn encode(&mut self, input: &CellInput) -> &[f32] {
        let n = input.len();
        let first = self.inputs.len();
        self.inputs.extend_from(input);
        let grow = |v: &mut Vec<f32>, per: usize| {
            let start = v.len();
            v.resize(start + n * per, 0.0);
            start
        };
        let s1 = grow(&mut self.y1, self.first.out_len());
        let s2 = grow(&mut self.y2, self.conv.out_len());
        let sf = grow(&mut self.features, self.fc.outputs);
        self.first.forward(
            &self.inputs,
            first,
            n,
            &self.table,
            &self.b1,
            &mut self.y1[s1..],
        );
        self.conv.forward(
            &self.y1[s1..],
            n,
            &self.w2,
            &self.b2,
            &mut self.y2[s2..],
            &mut self.scratch,
        );
        self.fc.forward(
            &self.y2[s2..],
            n,
            &self.wf_t,
            &self.bf,
            &mut self.features[sf..],
        );
        &self.features[sf..]
    }

    /// The features of every observation encoded since [`Self::load`],
    /// `[N, hidden]` row-major.
    pub fn features(&self) -> &[f32] {
        &self.features
    }

    /// Width of the features.
    pub fn width(&self) -> usize {
        self.fc.outputs
    }

    /// The backward pass over every observation encoded since
    /// [`Self::load`], in order: `dfeatures` `[N, hidden]` is the loss's
    /// gradient with respect to their features. Returns the gradients of
    /// [`Trunk::encoder_parameters`], in tch's layouts.
    pub fn backward(&mut self, dfeatures: &[f32]) -> [Tensor; 6] {
        let n = self.inputs.len();
        assert_eq!(
            dfeatures.len(),
            n * self.fc.outputs,
            "one feature gradient per encoded observation"
        );
        let mut df = dfeatures.to_vec();
        let (mut dwf, mut dbf) = (vec![0f32; self.wf.len()], vec![0f32; self.fc.outputs]);
        let mut dy2 = vec![0f32; self.y2.len()];
        self.fc.backward(
            &self.y2,
            n,
            &self.wf,
            &self.features,
            &mut df,
            &mut dwf,
            &mut dbf,
            Some(&mut dy2),
        );
        // The convolutions chunk by chunk, so that a chunk's input gradient
        // is still in the cache when the first convolution's backward reads
        // it.
        const CHUNK: usize = 32;
        let (mut dw2, mut db2) = (vec![0f32; self.w2.len()], vec![0f32; self.conv.cout]);
        let (mut dtable, mut db1) = (vec![0f32; self.table.len()], vec![0f32; self.first.out]);
        let (l1, l2) = (self.first.out_len(), self.conv.out_len());
        let mut dy1 = vec![0f32; CHUNK.min(n) * l1];
        let mut start = 0;
        while start < n {
            let m = CHUNK.min(n - start);
            let dy1 = &mut dy1[..m * l1];
            dy1.fill(0.0);
            let y1 = &self.y1[start * l1..][..m * l1];
            self.conv.backward(
                y1,
                m,
                &self.w2,
                &self.y2[start * l2..][..m * l2],
                &mut dy2[start * l2..][..m * l2],
                &mut dw2,
                &mut db2,
                Some(&mut *dy1),
                &mut self.scratch,
            );
            self.first
                .backward(&self.inputs, start, m, y1, dy1, &mut dtable, &mut db1);
            start += m;
        }
        // Back to tch's layouts.
        let (inputs, hidden) = (self.fc.inputs, self.fc.outputs);
        let mut dwf_torch = vec![0f32; dwf.len()];
        for o in 0..hidden {
            let (own, torch) = (
                &dwf[o * inputs..][..inputs],
                &mut dwf_torch[o * inputs..][..inputs],
            );
            for (&g, &col) in own.iter().zip(&self.fc_columns) {
                torch[col] = g;
            }
        }
        let [c1, c2] = [self.first.out as i64, self.conv.cout as i64];
        let channels = self.first.channels as i64;
        [
            Tensor::from_slice(&self.first.torch_weight(&dtable)).view([c1, channels, 3, 3]),
            Tensor::from_slice(&db1),
            Tensor::from_slice(&self.conv.torch_weight(&dw2)).view([c2, c1, 3, 3]),
            Tensor::from_slice(&db2),
            Tensor::from_slice(&dwf_torch).view([hidden as i64, inputs as i64]),
            Tensor::from_slice(&dbf),
        ]
    }
}

/// A loss with the value of `loss` whose gradient with respect to each
/// `params[k]` is `grads[k]` (undefined gradients count as zero):
/// `loss.detach() + Σ_k Σ grads[k] ⊙ (params[k] − params[k].detach())`.
/// The added terms are exactly 0 in value, and their gradient is
/// `grads[k]` exactly, so the caller's `backward` (and its clipping and
/// optimiser step) sees the gradients computed here as if autograd had.
pub fn with_gradients(loss: &Tensor, params: &[Tensor], grads: &[Tensor]) -> Tensor {
    let terms: Vec<Tensor> = params
        .iter()
        .zip(grads)
        .filter(|(p, g)| g.defined() && p.requires_grad())
        .map(|(p, g)| (g * (p - p.detach())).sum(Kind::Float))
        .collect();
    if terms.is_empty() {
        return loss.detach();
    }
    loss.detach() + Tensor::stack(&terms, 0).sum(Kind::Float)
}
