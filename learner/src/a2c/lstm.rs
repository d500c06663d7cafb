//! The LSTM core of every actor-critic (section 4.1: `π_g`, the A2C
//! baseline and the Worker are recurrent) and its linear heads, as kernels
//! of the project's own over one GEMM ([`crate::a2c::gemm`]), forward one
//! step at a time and backward through time over a whole rollout.
//!
//! The cell is `nn::lstm`'s (PyTorch's gate order `i, f, g, o`):
//!
//! ```text
//! z = x·W_ihᵀ + h·W_hhᵀ + b_ih + b_hh        [B, 4H]
//! i, f, o = σ(z_i), σ(z_f), σ(z_o);  g = tanh(z_g)
//! c' = f ⊙ c + i ⊙ g;  h' = o ⊙ tanh(c')
//! ```
//!
//! Its backward, given `dh'` and `dc'`: `dc = dc' + dh' ⊙ o ⊙ (1 − tanh²c')`,
//! `dz_i = dc ⊙ g ⊙ i(1 − i)`, `dz_f = dc ⊙ c ⊙ f(1 − f)`,
//! `dz_g = dc ⊙ i ⊙ (1 − g²)`, `dz_o = dh' ⊙ tanh c' ⊙ o(1 − o)`, and the
//! state's gradients `dc·f` and `dz·W_hh`. Over a rollout only that last
//! product is per step: the weight gradients and the input gradient are
//! three GEMMs over all `T·B` rows at once ([`LstmCell::weight_gradients`]).
//!
//! `σ` and `tanh` are evaluated through one vectorisable `exp` (Cephes'
//! `expf`, relative error below 2e-7), so the element-wise loops run under
//! the kernels' SIMD dispatch. tch stays the reference: the tests compare
//! outputs and gradients with tch's `lstm_cell`.

pub use super::gemm::transposed;
use super::gemm::{Mat, matmul};
use super::kernels::vectorized;

/// The cell's shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LstmCell {
    /// Input features.
    pub input: usize,
    /// Hidden (and cell) state width.
    pub hidden: usize,
}

/// `e^x`, Cephes' `expf` (range reduction by `ln 2`, a degree-6
/// polynomial), written so that it vectorises: no branch, no table, no
/// float-to-integer conversion (the integer `n` and `2ⁿ` come out of the
/// bits of `x·log₂e + 1.5·2²³`).
#[inline(always)]
fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    /// `1.5·2²³`: adding it rounds to an integer, kept in the low bits.
    const MAGIC: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let t = x * LOG2E + MAGIC;
    let n = t - MAGIC;
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = ((((1.987_569_2e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 5.0e-1;
    let p = p * r * r + r + 1.0;
    let pow2 = t.to_bits().wrapping_sub(MAGIC.to_bits()).wrapping_add(127) << 23;
    f32::from_bits(pow2) * p
}

/// The logistic function.
#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

/// The hyperbolic tangent, `1 − 2 / (e^{2x} + 1)` (absolute error about
/// 1e-7).
#[inline(always)]
fn tanh(x: f32) -> f32 {
    1.0 - 2.0 / (exp(2.0 * x) + 1.0)
}

/// One step's activations kept for the backward pass, rows `[n, ·]`.
#[derive(Debug)]
pub struct StepActivations<'a> {
    /// The activated gates `i, f, g, o` `[n, 4H]`.
    pub gates: &'a [f32],
    /// The cell state the step started from `[n, H]`.
    pub c_in: &'a [f32],
    /// `tanh` of the cell state it produced `[n, H]`.
    pub tanh_c: &'a [f32],
}

/// The activations of a sequence of steps, `[rows, ·]` step-major, for
/// [`LstmCell::backward_through_time`].
#[derive(Debug)]
pub struct Sequence<'a> {
    /// The activated gates `[rows, 4H]`.
    pub gates: &'a [f32],
    /// The cell state each step started from `[rows, H]`.
    pub c_in: &'a [f32],
    /// `tanh` of the cell state each step produced `[rows, H]`.
    pub tanh_c: &'a [f32],
    /// Whether row `t·n + b`'s state continues step `t − 1`'s output.
    pub continues: &'a [bool],
}

impl LstmCell {
    /// One step over `n` rows: the activated gates into `gates` `[n, 4H]`,
    /// the new cell state into `c_out`, `tanh` of it into `tanh_c` and the
    /// new hidden state into `h_out` (`[n, H]` each). `w_ih_t` `[I, 4H]`
    /// and `w_hh_t` `[H, 4H]` are tch's weights transposed ([`transposed`]:
    /// the GEMM runs about twice as fast with its right operand row-major
    /// at these shapes); `bias` is `b_ih + b_hh`.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        x: &[f32],
        h: &[f32],
        c: &[f32],
        n: usize,
        w_ih_t: &[f32],
        w_hh_t: &[f32],
        bias: &[f32],
        gates: &mut [f32],
        c_out: &mut [f32],
        tanh_c: &mut [f32],
        h_out: &mut [f32],
    ) {
        let (hd, g4) = (self.hidden, 4 * self.hidden);
        vectorized(
            #[inline(always)]
            || {
                let z = &mut gates[..n * g4];
                for row in z.chunks_exact_mut(g4) {
                    row.copy_from_slice(bias);
                }
                matmul(
                    z,
                    Mat::rows(x, n, self.input),
                    Mat::rows(w_ih_t, self.input, g4),
                    true,
                );
                matmul(z, Mat::rows(h, n, hd), Mat::rows(w_hh_t, hd, g4), true);
                for (r, zr) in z.chunks_exact_mut(g4).enumerate() {
                    let (ifg, zo) = zr.split_at_mut(3 * hd);
                    let (zif, zg) = ifg.split_at_mut(2 * hd);
                    for v in zif.iter_mut() {
                        *v = sigmoid(*v);
                    }
                    for v in zo.iter_mut() {
                        *v = sigmoid(*v);
                    }
                    for v in zg.iter_mut() {
                        *v = tanh(*v);
                    }
                    let (zi, zf) = zif.split_at(hd);
                    let rows = r * hd..(r + 1) * hd;
                    let gates = zi.iter().zip(zf.iter()).zip(zg.iter()).zip(zo.iter());
                    let outputs = c_out[rows.clone()]
                        .iter_mut()
                        .zip(tanh_c[rows.clone()].iter_mut())
                        .zip(h_out[rows.clone()].iter_mut());
                    for ((((&i, &f), &g), &o), (((co, tc), ho), &cp)) in
                        gates.zip(outputs.zip(c[rows].iter()))
                    {
                        let cn = f * cp + i * g;
                        let t = tanh(cn);
                        *co = cn;
                        *tc = t;
                        *ho = o * t;
                    }
                }
            },
        )
    }

    /// The backward pass of one step of [`Self::forward`] over `n` rows:
    /// from the gradients `dh` of its hidden output and `dc` of its cell
    /// output (`[n, H]`; `dc` is overwritten with the gradient of the cell
    /// state the step started from), writes the gradient of the gate
    /// pre-activations into `dz` `[n, 4H]` and of the hidden state the step
    /// started from into `dh_in` `[n, H]`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward_step(
        &self,
        act: &StepActivations<'_>,
        n: usize,
        w_hh: &[f32],
        dh: &[f32],
        dc: &mut [f32],
        dz: &mut [f32],
        dh_in: &mut [f32],
    ) {
        let (hd, g4) = (self.hidden, 4 * self.hidden);
        vectorized(
            #[inline(always)]
            || {
                for r in 0..n {
                    let gr = &act.gates[r * g4..][..g4];
                    let (gi, rest) = gr.split_at(hd);
                    let (gf, rest) = rest.split_at(hd);
                    let (gg, go) = rest.split_at(hd);
                    let dzr = &mut dz[r * g4..][..g4];
                    let (dzi, rest) = dzr.split_at_mut(hd);
                    let (dzf, rest) = rest.split_at_mut(hd);
                    let (dzg, dzo) = rest.split_at_mut(hd);
                    let cin = &act.c_in[r * hd..][..hd];
                    let tc = &act.tanh_c[r * hd..][..hd];
                    let dhr = &dh[r * hd..][..hd];
                    let dcr = &mut dc[r * hd..][..hd];
                    for k in 0..hd {
                        let (i, f, g, o) = (gi[k], gf[k], gg[k], go[k]);
                        let dct = dcr[k] + dhr[k] * o * (1.0 - tc[k] * tc[k]);
                        dzi[k] = dct * g * i * (1.0 - i);
                        dzf[k] = dct * cin[k] * f * (1.0 - f);
                        dzg[k] = dct * i * (1.0 - g * g);
                        dzo[k] = dhr[k] * tc[k] * o * (1.0 - o);
                        dcr[k] = dct * f;
                    }
                }
                matmul(
                    &mut dh_in[..n * hd],
                    Mat::rows(dz, n, g4),
                    Mat::rows(w_hh, g4, hd),
                    false,
                );
            },
        )
    }

    /// The backward pass through time over the `rows / n` steps of `n`
    /// rows each whose activations `seq` holds (step-major, `[rows, ·]`):
    /// from the gradient `dh_out` `[rows, H]` each step's hidden output
    /// receives from outside the core (the heads), writes the gradient of
    /// every step's gate pre-activations into `dz` `[rows, 4H]` (what
    /// [`Self::weight_gradients`] reads). A row whose state does not
    /// continue the previous step's output (`seq.continues` false: a reset,
    /// or the sequence's first step) passes no gradient back.
    pub fn backward_through_time(
        &self,
        n: usize,
        w_hh: &[f32],
        seq: &Sequence<'_>,
        dh_out: &[f32],
        dz: &mut [f32],
    ) {
        let (hd, g4) = (self.hidden, 4 * self.hidden);
        let steps = seq.continues.len() / n.max(1);
        let (mut dh, mut dc) = (vec![0f32; n * hd], vec![0f32; n * hd]);
        let mut dh_in = vec![0f32; n * hd];
        for t in (0..steps).rev() {
            let s = t * n * hd;
            for (d, g) in dh.iter_mut().zip(&dh_out[s..][..n * hd]) {
                *d += g;
            }
            let act = StepActivations {
                gates: &seq.gates[t * n * g4..][..n * g4],
                c_in: &seq.c_in[s..][..n * hd],
                tanh_c: &seq.tanh_c[s..][..n * hd],
            };
            self.backward_step(
                &act,
                n,
                w_hh,
                &dh,
                &mut dc,
                &mut dz[t * n * g4..],
                &mut dh_in,
            );
            for b in 0..n {
                let row = b * hd..(b + 1) * hd;
                if seq.continues[t * n + b] {
                    dh[row.clone()].copy_from_slice(&dh_in[row]);
                } else {
                    dh[row.clone()].fill(0.0);
                    dc[row].fill(0.0);
                }
            }
        }
    }

    /// The gradients over all `rows` steps of a rollout from their gate
    /// pre-activation gradients `dz` `[rows, 4H]`, their inputs `x`
    /// `[rows, I]` and the hidden states they started from `h_in`
    /// `[rows, H]`: adds into `dw_ih` `[4H, I]`, `dw_hh` `[4H, H]` and
    /// `dbias` `[4H]` (the gradient of `b_ih` and of `b_hh` alike) and
    /// writes the input gradient into `dx` `[rows, I]`.
    #[allow(clippy::too_many_arguments)]
    pub fn weight_gradients(
        &self,
        dz: &[f32],
        x: &[f32],
        h_in: &[f32],
        rows: usize,
        w_ih: &[f32],
        dw_ih: &mut [f32],
        dw_hh: &mut [f32],
        dbias: &mut [f32],
        dx: &mut [f32],
    ) {
        let (hd, g4, i) = (self.hidden, 4 * self.hidden, self.input);
        vectorized(
            #[inline(always)]
            || {
                let dzm = Mat::rows(dz, rows, g4);
                matmul(dw_ih, dzm.t(), Mat::rows(x, rows, i), true);
                matmul(dw_hh, dzm.t(), Mat::rows(h_in, rows, hd), true);
                matmul(&mut dx[..rows * i], dzm, Mat::rows(w_ih, g4, i), false);
                for row in dz[..rows * g4].chunks_exact(g4) {
                    for (b, d) in dbias.iter_mut().zip(row) {
                        *b += d;
                    }
                }
            },
        )
    }
}

/// The linear heads on the core's output: policy logits `[n, A]` and state
/// values `[n]` (tch's `nn::Linear` layouts: `w_pi` `[A, H]`, `w_v` `[1, H]`;
/// the forward takes `w_pi` transposed, `[H, A]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heads {
    /// Hidden width.
    pub hidden: usize,
    /// Actions.
    pub actions: usize,
}

impl Heads {
    /// Logits and values of `n` hidden rows (`w_pi_t` `[H, A]`).
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        h: &[f32],
        n: usize,
        w_pi_t: &[f32],
        b_pi: &[f32],
        w_v: &[f32],
        b_v: f32,
        logits: &mut [f32],
        values: &mut [f32],
    ) {
        let (hd, a) = (self.hidden, self.actions);
        vectorized(
            #[inline(always)]
            || {
                let out = &mut logits[..n * a];
                for row in out.chunks_exact_mut(a) {
                    row.copy_from_slice(b_pi);
                }
                matmul(out, Mat::rows(h, n, hd), Mat::rows(w_pi_t, hd, a), true);
                let values = &mut values[..n];
                values.fill(b_v);
                matmul(values, Mat::rows(h, n, hd), Mat::rows(w_v, hd, 1), true);
            },
        )
    }

    /// The backward pass over `n` rows: adds the weight and bias gradients
    /// into `dw_pi`, `db_pi`, `dw_v`, `db_v` and writes the gradient of the
    /// hidden rows into `dh` `[n, H]`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        h: &[f32],
        n: usize,
        w_pi: &[f32],
        w_v: &[f32],
        dlogits: &[f32],
        dvalues: &[f32],
        dw_pi: &mut [f32],
        db_pi: &mut [f32],
        dw_v: &mut [f32],
        db_v: &mut f32,
        dh: &mut [f32],
    ) {
        let (hd, a) = (self.hidden, self.actions);
        vectorized(
            #[inline(always)]
            || {
                let dl = Mat::rows(dlogits, n, a);
                let dv = Mat::rows(dvalues, n, 1);
                let hm = Mat::rows(h, n, hd);
                matmul(dw_pi, dl.t(), hm, true);
                matmul(dw_v, dv.t(), hm, true);
                for row in dlogits[..n * a].chunks_exact(a) {
                    for (b, d) in db_pi.iter_mut().zip(row) {
                        *b += d;
                    }
                }
                *db_v += dvalues[..n].iter().sum::<f32>();
                let dh = &mut dh[..n * hd];
                matmul(dh, dl, Mat::rows(w_pi, a, hd), false);
                matmul(dh, dv, Mat::rows(w_v, 1, hd), true);
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use tch::{Kind, Tensor};

    use super::*;

    use crate::a2c::kernels::tests::rel_diff;

    fn floats(t: &Tensor) -> Vec<f32> {
        Vec::<f32>::try_from(&t.contiguous().flatten(0, -1)).expect("floats")
    }

    fn rand(rng: &mut SmallRng, len: usize, scale: f32) -> Vec<f32> {
        (0..len).map(|_| rng.random_range(-scale..scale)).collect()
    }

    #[test]
    fn exp_sigmoid_and_tanh_are_within_a_few_ulp_of_the_standard_library() {
        for k in -4000..=4000 {
            let x = k as f32 * 0.02;
            let (e, se) = (exp(x), x.exp());
            assert!(((e - se) / se).abs() < 3e-7, "exp({x}): {e} vs {se}");
            assert!(
                (sigmoid(x) - 1.0 / (1.0 + (-x).exp())).abs() < 2e-7,
                "σ({x})"
            );
            assert!((tanh(x) - x.tanh()).abs() < 3e-7, "tanh({x})");
        }
        // Far outside the clamp: finite, in range, not NaN.
        assert!(
            (0.0..1e-30).contains(&sigmoid(-200.0)),
            "σ(-200) = {}",
            sigmoid(-200.0)
        );
        assert!(sigmoid(200.0) == 1.0 && tanh(200.0) == 1.0 && tanh(-200.0) == -1.0);
    }

    /// A rollout of `steps` steps of `n` rows through the cell and the
    /// heads, with the state reset for some rows between steps, against
    /// tch's `lstm_cell` and `linear` with autograd: every output and every
    /// gradient (weights, biases, inputs) to 1e-5 of its largest magnitude.
    #[test]
    fn the_cell_and_heads_equal_tch_forward_and_backward_through_time() {
        let mut rng = SmallRng::seed_from_u64(5);
        for (input, hidden, actions, n, steps) in [(128, 128, 3, 7, 9), (40, 24, 5, 3, 4)] {
            let cell = LstmCell { input, hidden };
            let heads = Heads { hidden, actions };
            let g4 = 4 * hidden;
            let w_ih = rand(&mut rng, g4 * input, 0.2);
            let w_hh = rand(&mut rng, g4 * hidden, 0.2);
            let (b_ih, b_hh) = (rand(&mut rng, g4, 0.5), rand(&mut rng, g4, 0.5));
            let (w_pi, b_pi) = (
                rand(&mut rng, actions * hidden, 0.3),
                rand(&mut rng, actions, 0.3),
            );
            let (w_v, b_v) = (rand(&mut rng, hidden, 0.3), 0.7f32);
            let xs = rand(&mut rng, steps * n * input, 2.0);
            let h0 = rand(&mut rng, n * hidden, 1.0);
            let c0 = rand(&mut rng, n * hidden, 1.0);
            let keep: Vec<f32> = (0..steps * n)
                .map(|_| f32::from(u8::from(rng.random_bool(0.7))))
                .collect();
            let dlogits = rand(&mut rng, steps * n * actions, 1.0);
            let dvalues = rand(&mut rng, steps * n, 1.0);

            // tch, with autograd.
            let leaf = |v: &[f32], shape: &[i64]| {
                Tensor::from_slice(v).view(shape).set_requires_grad(true)
            };
            let (hi, gi) = (hidden as i64, g4 as i64);
            let tw_ih = leaf(&w_ih, &[gi, input as i64]);
            let tw_hh = leaf(&w_hh, &[gi, hi]);
            let (tb_ih, tb_hh) = (leaf(&b_ih, &[gi]), leaf(&b_hh, &[gi]));
            let tw_pi = leaf(&w_pi, &[actions as i64, hi]);
            let tb_pi = leaf(&b_pi, &[actions as i64]);
            let tw_v = leaf(&w_v, &[1, hi]);
            let tb_v = leaf(&[b_v], &[1]);
            let tx = leaf(&xs, &[steps as i64, n as i64, input as i64]);
            let (mut th, mut tc) = (
                Tensor::from_slice(&h0).view([n as i64, hi]),
                Tensor::from_slice(&c0).view([n as i64, hi]),
            );
            let mut loss = Tensor::zeros([], (Kind::Float, tch::Device::Cpu));
            let mut t_logits = Vec::new();
            for t in 0..steps {
                if t > 0 {
                    let k = Tensor::from_slice(&keep[t * n..][..n]).view([n as i64, 1]);
                    th = &th * &k;
                    tc = &tc * &k;
                }
                let (h, c) = tx.get(t as i64).lstm_cell(
                    &[&th, &tc],
                    &tw_ih,
                    &tw_hh,
                    Some(&tb_ih),
                    Some(&tb_hh),
                );
                let logits = h.linear(&tw_pi, Some(&tb_pi));
                let values = h.linear(&tw_v, Some(&tb_v)).squeeze_dim(-1);
                let dl = Tensor::from_slice(&dlogits[t * n * actions..][..n * actions])
                    .view([n as i64, actions as i64]);
                let dv = Tensor::from_slice(&dvalues[t * n..][..n]);
                loss = loss + (&logits * dl).sum(Kind::Float) + (&values * dv).sum(Kind::Float);
                t_logits.extend(floats(&logits.detach()));
                th = h;
                tc = c;
            }
            loss.backward();

            // Own kernels.
            let bias: Vec<f32> = b_ih.iter().zip(&b_hh).map(|(a, b)| a + b).collect();
            let (w_ih_t, w_hh_t) = (transposed(&w_ih, g4, input), transposed(&w_hh, g4, hidden));
            let w_pi_t = transposed(&w_pi, actions, hidden);
            let rows = steps * n;
            let (mut h_in, mut c_in) = (vec![0f32; rows * hidden], vec![0f32; rows * hidden]);
            let mut gates = vec![0f32; rows * g4];
            let (mut tanh_c, mut h_out) = (vec![0f32; rows * hidden], vec![0f32; rows * hidden]);
            let mut c_out = vec![0f32; rows * hidden];
            let (mut logits, mut values) = (vec![0f32; rows * actions], vec![0f32; rows]);
            for t in 0..steps {
                let s = t * n * hidden;
                for r in 0..n * hidden {
                    let k = if t == 0 {
                        1.0
                    } else {
                        keep[t * n + r / hidden]
                    };
                    h_in[s + r] = if t == 0 {
                        h0[r]
                    } else {
                        h_out[s - n * hidden + r] * k
                    };
                    c_in[s + r] = if t == 0 {
                        c0[r]
                    } else {
                        c_out[s - n * hidden + r] * k
                    };
                }
                let (hs, cs) = (
                    h_in[s..][..n * hidden].to_vec(),
                    c_in[s..][..n * hidden].to_vec(),
                );
                cell.forward(
                    &xs[t * n * input..],
                    &hs,
                    &cs,
                    n,
                    &w_ih_t,
                    &w_hh_t,
                    &bias,
                    &mut gates[t * n * g4..],
                    &mut c_out[s..],
                    &mut tanh_c[s..],
                    &mut h_out[s..],
                );
                heads.forward(
                    &h_out[s..],
                    n,
                    &w_pi_t,
                    &b_pi,
                    &w_v,
                    b_v,
                    &mut logits[t * n * actions..],
                    &mut values[t * n..],
                );
            }
            assert!(rel_diff(&logits, &t_logits) < 1e-5, "logits");

            let (mut dw_pi, mut db_pi) = (vec![0f32; w_pi.len()], vec![0f32; actions]);
            let (mut dw_v, mut db_v) = (vec![0f32; hidden], 0f32);
            let mut dh_all = vec![0f32; rows * hidden];
            heads.backward(
                &h_out,
                rows,
                &w_pi,
                &w_v,
                &dlogits,
                &dvalues,
                &mut dw_pi,
                &mut db_pi,
                &mut dw_v,
                &mut db_v,
                &mut dh_all,
            );
            let mut dz = vec![0f32; rows * g4];
            let (mut dh, mut dc) = (vec![0f32; n * hidden], vec![0f32; n * hidden]);
            let mut dh_in = vec![0f32; n * hidden];
            for t in (0..steps).rev() {
                let s = t * n * hidden;
                for (d, g) in dh.iter_mut().zip(&dh_all[s..][..n * hidden]) {
                    *d += g;
                }
                let act = StepActivations {
                    gates: &gates[t * n * g4..][..n * g4],
                    c_in: &c_in[s..][..n * hidden],
                    tanh_c: &tanh_c[s..][..n * hidden],
                };
                cell.backward_step(
                    &act,
                    n,
                    &w_hh,
                    &dh,
                    &mut dc,
                    &mut dz[t * n * g4..],
                    &mut dh_in,
                );
                for r in 0..n * hidden {
                    let k = if t == 0 {
                        1.0
                    } else {
                        keep[t * n + r / hidden]
                    };
                    dh[r] = dh_in[r] * k;
                    dc[r] *= k;
                }
            }
            let (mut dw_ih, mut dw_hh) = (vec![0f32; w_ih.len()], vec![0f32; w_hh.len()]);
            let (mut dbias, mut dx) = (vec![0f32; g4], vec![0f32; rows * input]);
            cell.weight_gradients(
                &dz, &xs, &h_in, rows, &w_ih, &mut dw_ih, &mut dw_hh, &mut dbias, &mut dx,
            );
            let grad = |t: &Tensor| floats(&t.grad());
            for (name, own, reference) in [
                ("w_ih", &dw_ih, grad(&tw_ih)),
                ("w_hh", &dw_hh, grad(&tw_hh)),
                ("b_ih", &dbias, grad(&tb_ih)),
                ("b_hh", &dbias, grad(&tb_hh)),
                ("w_pi", &dw_pi, grad(&tw_pi)),
                ("b_pi", &db_pi, grad(&tb_pi)),
                ("w_v", &dw_v, grad(&tw_v)),
                ("x", &dx, grad(&tx)),
            ] {
                let d = rel_diff(own, &reference);
                assert!(d < 1e-5, "{name}: relative difference {d:e}");
            }
            assert!((db_v - grad(&tb_v)[0]).abs() < 1e-4, "b_v");
            // And the state's own gradient is what flowed into step 0's
            // (not a parameter; checked through dx and the weights).
        }
    }
}
