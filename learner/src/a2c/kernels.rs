//! The encoder's layers (Shang et al. 2019 give `π_g` and the agents "a
//! CNN encoding" of the bird's-eye maze; here 3×3 conv → ReLU → 3×3 conv
//! of stride 2 → ReLU → linear → ReLU, [`crate::a2c::net`]) as kernels of
//! the project's own, in plain Rust over one GEMM ([`crate::a2c::gemm`]),
//! forward and backward, each with its ReLU folded in.
//!
//! - [`FirstConv`]: the first convolution over the one-hot planes as a sum
//!   of kernel columns, one per input that is 1 under the kernel
//!   ([`CellInput::for_each_position`], [`CellInput::for_each_mark`]); its backward adds the output gradient
//!   into the same columns.
//! - [`StridedConv`]: the stride-2 convolution as an im2col into a buffer
//!   and one GEMM per chunk of observations; its backward is
//!   `dW = colsᵀ · dZ`, `dX = col2im(dZ · Wᵀ)`, the bias gradient a column
//!   sum.
//! - [`DenseRelu`]: the fully connected layer, three GEMMs.
//!
//! Activations are channels-last (`[N, H, W, C]`), so each kernel tap's
//! patch is one contiguous run of `C` floats. tch stays the reference: the
//! tests check every output and gradient against tch's.

use super::gemm::{Mat, matmul};
use super::input::CellInput;

/// Positions of a 3×3 kernel.
const TAPS: usize = 9;

/// Rows of the im2col buffer per chunk: a few hundred KB of patches, so a
/// chunk's patches stay in the cache between the GEMMs that read them.
const CHUNK_ROWS: usize = 1024;

/// Runs `f` compiled for the widest SIMD instruction set the CPU has
/// (pulp's run-time dispatch: AVX-512 or AVX2 on x86-64), so the kernels'
/// element-wise loops vectorise past the baseline SSE2 the crate is built
/// for. What `f` calls must inline into it (`#[inline(always)]`) to share
/// the instruction set.
#[inline(always)]
pub(crate) fn vectorized<R>(f: impl FnOnce() -> R) -> R {
    struct Op<F>(F);
    impl<R, F: FnOnce() -> R> pulp::WithSimd for Op<F> {
        type Output = R;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) -> R {
            (self.0)()
        }
    }
    pulp::Arch::new().dispatch(Op(f))
}

/// The channel count of the encoder's convolutions' activations, given
/// straight-line code in the loops over channel runs.
const RUN: usize = 16;

/// Adds `src` into `dst` element by element.
#[inline(always)]
fn add_into(dst: &mut [f32], src: &[f32]) {
    if let (Ok(d), Ok(s)) = (
        <&mut [f32; RUN]>::try_from(&mut *dst),
        <&[f32; RUN]>::try_from(src),
    ) {
        // Whole loads before the store: the run adds as one vector even
        // where the compiler cannot rule out that `dst` and `src` overlap.
        let (mut acc, s) = (*d, *s);
        for (a, s) in acc.iter_mut().zip(s) {
            *a += s;
        }
        *d = acc;
    } else {
        for (d, s) in dst.iter_mut().zip(src) {
            *d += s;
        }
    }
}

/// Copies `src` into `dst` (one channel run).
#[inline(always)]
fn copy_run(dst: &mut [f32], src: &[f32]) {
    if let (Ok(d), Ok(s)) = (
        <&mut [f32; RUN]>::try_from(&mut *dst),
        <&[f32; RUN]>::try_from(src),
    ) {
        *d = *s;
    } else {
        dst.copy_from_slice(src);
    }
}

/// `v = relu(v + bias)` over rows of `bias.len()` columns.
#[inline(always)]
fn bias_relu(y: &mut [f32], bias: &[f32]) {
    for row in y.chunks_exact_mut(bias.len()) {
        for (v, b) in row.iter_mut().zip(bias) {
            *v = (*v + b).max(0.0);
        }
    }
}

/// The ReLU's backward as tch's (no gradient where its input was ≤ 0):
/// zeroes `dy` where the output `y` is 0, and adds the rows of the result
/// (`width` columns) into the bias gradient `dbias`.
#[inline(always)]
fn relu_backward(dy: &mut [f32], y: &[f32], dbias: &mut [f32]) {
    let width = dbias.len();
    for (drow, yrow) in dy.chunks_exact_mut(width).zip(y.chunks_exact(width)) {
        for ((d, &v), b) in drow.iter_mut().zip(yrow).zip(dbias.iter_mut()) {
            *d = if v > 0.0 { *d } else { 0.0 };
            *b += *d;
        }
    }
}

/// The first 3×3 convolution (stride 1, zero padding 1) over the one-hot
/// planes of a [`CellInput`], followed by a ReLU: output
/// `[N, height, width, out]`. Its weight is the table `[channels·9, out]`,
/// row `channel·9 + tap` the kernel column `W[:, channel, ky, kx]`
/// ([`FirstConv::table`]); the output at a position is the bias plus the
/// rows of the inputs that are 1 under the kernel, about ten of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FirstConv {
    /// Grid columns.
    pub width: usize,
    /// Grid rows.
    pub height: usize,
    /// Input planes.
    pub channels: usize,
    /// Output channels.
    pub out: usize,
}

impl FirstConv {
    /// Floats of one observation's output.
    pub fn out_len(&self) -> usize {
        self.width * self.height * self.out
    }

    /// The table `[channels·9, out]` of a tch kernel `[out, channels, 3, 3]`.
    pub fn table(&self, torch: &[f32]) -> Vec<f32> {
        debug_assert_eq!(torch.len(), self.out * self.channels * TAPS);
        let mut t = vec![0f32; torch.len()];
        for o in 0..self.out {
            for r in 0..self.channels * TAPS {
                t[r * self.out + o] = torch[o * self.channels * TAPS + r];
            }
        }
        t
    }

    /// A gradient of the table back in tch's layout `[out, channels, 3, 3]`.
    pub fn torch_weight(&self, table: &[f32]) -> Vec<f32> {
        let mut w = vec![0f32; table.len()];
        for o in 0..self.out {
            for r in 0..self.channels * TAPS {
                w[o * self.channels * TAPS + r] = table[r * self.out + o];
            }
        }
        w
    }

    /// `y = relu(conv(x) + bias)` of the `n` observations of `input` from
    /// `first` on.
    pub fn forward(
        &self,
        input: &CellInput,
        first: usize,
        n: usize,
        table: &[f32],
        bias: &[f32],
        y: &mut [f32],
    ) {
        vectorized(
            #[inline(always)]
            || {
                debug_assert_eq!(input.channels(), self.channels);
                let out = self.out;
                for (j, yi) in y[..n * self.out_len()]
                    .chunks_exact_mut(self.out_len())
                    .enumerate()
                {
                    // Each position's sum in registers, stored once.
                    input.for_each_position(
                        first + j,
                        #[inline(always)]
                        |p, rows| {
                            let dst = &mut yi[p * out..][..out];
                            if let Ok(dst) = <&mut [f32; RUN]>::try_from(&mut *dst) {
                                let mut acc = [0f32; RUN];
                                for &r in rows {
                                    let row: &[f32; RUN] = table[r * RUN..][..RUN]
                                        .try_into()
                                        .expect("invariant: a run of RUN floats");
                                    for (a, v) in acc.iter_mut().zip(row) {
                                        *a += v;
                                    }
                                }
                                *dst = acc;
                            } else {
                                dst.fill(0.0);
                                for &r in rows {
                                    add_into(dst, &table[r * out..][..out]);
                                }
                            }
                        },
                    );
                    input.for_each_mark(
                        first + j,
                        #[inline(always)]
                        |p, r| add_into(&mut yi[p * out..][..out], &table[r * out..][..out]),
                    );
                    bias_relu(yi, bias);
                }
            },
        )
    }

    /// The backward pass of [`Self::forward`]: `dy` (the gradient of the
    /// ReLU's output, overwritten with that of its input) and `y` (the
    /// forward output); adds the table's gradient into `dtable` and the
    /// bias gradient into `dbias`. (The input is data: no gradient.)
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        input: &CellInput,
        first: usize,
        n: usize,
        y: &[f32],
        dy: &mut [f32],
        dtable: &mut [f32],
        dbias: &mut [f32],
    ) {
        vectorized(
            #[inline(always)]
            || {
                let out = self.out;
                let dy = &mut dy[..n * self.out_len()];
                relu_backward(dy, y, dbias);
                // Consecutive positions add into the same rows (a floor
                // cell's under every tap); spreading them over a few copies
                // of the table keeps those adds from waiting on each other.
                const COPIES: usize = 4;
                let len = dtable.len();
                let mut copies = vec![0f32; COPIES * len];
                for (j, dzi) in dy.chunks_exact(self.out_len()).enumerate() {
                    input.for_each_position(
                        first + j,
                        #[inline(always)]
                        |p, rows| {
                            let dt = &mut copies[(p % COPIES) * len..][..len];
                            let g = &dzi[p * out..][..out];
                            for &r in rows {
                                add_into(&mut dt[r * out..][..out], g);
                            }
                        },
                    );
                    input.for_each_mark(
                        first + j,
                        #[inline(always)]
                        |p, r| {
                            add_into(&mut copies[r * out..][..out], &dzi[p * out..][..out]);
                        },
                    );
                }
                for copy in copies.chunks_exact(len) {
                    for (d, c) in dtable.iter_mut().zip(copy) {
                        *d += c;
                    }
                }
            },
        )
    }
}

/// A 3×3 convolution with stride 2 and zero padding 1 followed by a ReLU,
/// over channels-last activations: input `[N, height, width, cin]`,
/// output `[N, ⌈height/2⌉, ⌈width/2⌉, cout]`. Its weight is the GEMM
/// operand `[9·cin, cout]`, row `tap·cin + c` for input channel `c` at tap
/// `tap = 3·ky + kx` ([`StridedConv::gemm_weight`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StridedConv {
    /// Input rows.
    pub height: usize,
    /// Input columns.
    pub width: usize,
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
}

impl StridedConv {
    /// Output `(rows, columns)`: `(⌈height/2⌉, ⌈width/2⌉)`.
    pub fn out_hw(&self) -> (usize, usize) {
        (self.height.div_ceil(2), self.width.div_ceil(2))
    }

    /// Floats of one observation's input.
    pub fn in_len(&self) -> usize {
        self.height * self.width * self.cin
    }

    /// Floats of one observation's output.
    pub fn out_len(&self) -> usize {
        let (ho, wo) = self.out_hw();
        ho * wo * self.cout
    }

    /// Multiply-adds of one observation's forward pass.
    pub fn macs(&self) -> usize {
        let (ho, wo) = self.out_hw();
        ho * wo * self.cout * self.cin * TAPS
    }

    /// The GEMM weight `[9·cin, cout]` of a tch kernel `[cout, cin, 3, 3]`
    /// (row-major floats).
    pub fn gemm_weight(&self, torch: &[f32]) -> Vec<f32> {
        debug_assert_eq!(torch.len(), self.cout * self.cin * TAPS);
        let mut w = vec![0f32; torch.len()];
        for o in 0..self.cout {
            for c in 0..self.cin {
                for tap in 0..TAPS {
                    w[(tap * self.cin + c) * self.cout + o] =
                        torch[(o * self.cin + c) * TAPS + tap];
                }
            }
        }
        w
    }

    /// A gradient of the GEMM weight back in tch's layout `[cout, cin, 3, 3]`.
    pub fn torch_weight(&self, gemm: &[f32]) -> Vec<f32> {
        let mut w = vec![0f32; gemm.len()];
        for o in 0..self.cout {
            for c in 0..self.cin {
                for tap in 0..TAPS {
                    w[(o * self.cin + c) * TAPS + tap] = gemm[(tap * self.cin + c) * self.cout + o];
                }
            }
        }
        w
    }

    /// Observations per chunk.
    fn chunk(&self) -> usize {
        let (ho, wo) = self.out_hw();
        (CHUNK_ROWS / (ho * wo)).max(1)
    }

    /// The patches of `n` observations `x` as rows `[n·ho·wo, 9·cin]`.
    #[inline(always)]
    fn im2col(&self, x: &[f32], n: usize, cols: &mut [f32]) {
        let (h, w, cin) = (self.height, self.width, self.cin);
        let (ho, wo) = self.out_hw();
        let k = TAPS * cin;
        for i in 0..n {
            let xi = &x[i * h * w * cin..(i + 1) * h * w * cin];
            for oy in 0..ho {
                for ox in 0..wo {
                    let row = &mut cols[((i * ho + oy) * wo + ox) * k..][..k];
                    for ky in 0..3 {
                        let iy = (2 * oy + ky).wrapping_sub(1);
                        for kx in 0..3 {
                            let ix = (2 * ox + kx).wrapping_sub(1);
                            let dst = &mut row[(3 * ky + kx) * cin..][..cin];
                            if iy < h && ix < w {
                                copy_run(dst, &xi[(iy * w + ix) * cin..][..cin]);
                            } else {
                                dst.fill(0.0);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Adds the patch gradients `dcols` of `n` observations into `dx`
    /// (the transpose of [`Self::im2col`]).
    #[inline(always)]
    fn col2im_add(&self, dcols: &[f32], n: usize, dx: &mut [f32]) {
        let (h, w, cin) = (self.height, self.width, self.cin);
        let (ho, wo) = self.out_hw();
        let k = TAPS * cin;
        for i in 0..n {
            let dxi = &mut dx[i * h * w * cin..(i + 1) * h * w * cin];
            for oy in 0..ho {
                for ox in 0..wo {
                    let row = &dcols[((i * ho + oy) * wo + ox) * k..][..k];
                    for ky in 0..3 {
                        let iy = (2 * oy + ky).wrapping_sub(1);
                        if iy >= h {
                            continue;
                        }
                        for kx in 0..3 {
                            let ix = (2 * ox + kx).wrapping_sub(1);
                            if ix >= w {
                                continue;
                            }
                            add_into(
                                &mut dxi[(iy * w + ix) * cin..][..cin],
                                &row[(3 * ky + kx) * cin..][..cin],
                            );
                        }
                    }
                }
            }
        }
    }

    /// `y = relu(conv(x) + bias)` for `n` observations; `weight` is the
    /// GEMM weight. `scratch` is reused between calls.
    pub fn forward(
        &self,
        x: &[f32],
        n: usize,
        weight: &[f32],
        bias: &[f32],
        y: &mut [f32],
        scratch: &mut Vec<f32>,
    ) {
        vectorized(
            #[inline(always)]
            || {
                let (ho, wo) = self.out_hw();
                let (k, cout) = (TAPS * self.cin, self.cout);
                let wm = Mat::rows(weight, k, cout);
                let chunk = self.chunk();
                scratch.resize(chunk * ho * wo * k, 0.0);
                let mut start = 0;
                while start < n {
                    let m = chunk.min(n - start);
                    let rows = m * ho * wo;
                    let cols = &mut scratch[..rows * k];
                    self.im2col(&x[start * self.in_len()..], m, cols);
                    let out = &mut y[start * self.out_len()..][..rows * cout];
                    matmul(out, Mat::rows(cols, rows, k), wm, false);
                    bias_relu(out, bias);
                    start += m;
                }
            },
        )
    }

    /// The backward pass of [`Self::forward`] over `n` observations: `dy`
    /// (the gradient of the ReLU's output, overwritten with that of its
    /// input) and `y` (the forward output); adds the weight gradient
    /// (GEMM layout) into `dweight`, the bias gradient into `dbias` and,
    /// when given, the input gradient into `dx`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        x: &[f32],
        n: usize,
        weight: &[f32],
        y: &[f32],
        dy: &mut [f32],
        dweight: &mut [f32],
        dbias: &mut [f32],
        mut dx: Option<&mut [f32]>,
        scratch: &mut Vec<f32>,
    ) {
        vectorized(
            #[inline(always)]
            || {
                let (ho, wo) = self.out_hw();
                let (k, cout) = (TAPS * self.cin, self.cout);
                relu_backward(&mut dy[..n * self.out_len()], y, dbias);
                // `Wᵀ` row-major: the input gradient's product runs faster
                // with its right operand so ([`super::gemm::transposed`]).
                let weight_t = if dx.is_some() {
                    super::gemm::transposed(weight, k, cout)
                } else {
                    Vec::new()
                };
                let chunk = self.chunk();
                scratch.resize(2 * chunk * ho * wo * k, 0.0);
                let (cols_buf, dcols_buf) = scratch.split_at_mut(chunk * ho * wo * k);
                let mut start = 0;
                while start < n {
                    let m = chunk.min(n - start);
                    let rows = m * ho * wo;
                    let dz = &dy[start * self.out_len()..][..rows * cout];
                    let dz = Mat::rows(dz, rows, cout);
                    let cols = &mut cols_buf[..rows * k];
                    self.im2col(&x[start * self.in_len()..], m, cols);
                    matmul(dweight, Mat::rows(cols, rows, k).t(), dz, true);
                    if let Some(dx) = dx.as_deref_mut() {
                        let dcols = &mut dcols_buf[..rows * k];
                        matmul(dcols, dz, Mat::rows(&weight_t, cout, k), false);
                        self.col2im_add(dcols, m, &mut dx[start * self.in_len()..]);
                    }
                    start += m;
                }
            },
        )
    }
}

/// A fully connected layer followed by a ReLU, `y = relu(x · Wᵀ + b)`,
/// over row-major batches: input `[N, inputs]`, output `[N, outputs]`,
/// weight `[outputs, inputs]` as tch's `nn::linear` stores it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DenseRelu {
    /// Input features.
    pub inputs: usize,
    /// Output features.
    pub outputs: usize,
}

impl DenseRelu {
    /// `y = relu(x · Wᵀ + b)` for `n` rows, from `weight_t`, the weight
    /// `W` transposed (`[inputs, outputs]`, [`super::gemm::transposed`]).
    pub fn forward(&self, x: &[f32], n: usize, weight_t: &[f32], bias: &[f32], y: &mut [f32]) {
        vectorized(
            #[inline(always)]
            || {
                let (k, o) = (self.inputs, self.outputs);
                let out = &mut y[..n * o];
                matmul(out, Mat::rows(x, n, k), Mat::rows(weight_t, k, o), false);
                bias_relu(out, bias);
            },
        )
    }

    /// The backward pass of [`Self::forward`] over `n` rows: `dy` (the
    /// gradient of the ReLU's output, overwritten with that of its input)
    /// and `y` (the forward output); adds the weight gradient into
    /// `dweight` (`[outputs, inputs]`), the bias gradient into `dbias` and
    /// writes the input gradient into `dx` when given.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        x: &[f32],
        n: usize,
        weight: &[f32],
        y: &[f32],
        dy: &mut [f32],
        dweight: &mut [f32],
        dbias: &mut [f32],
        dx: Option<&mut [f32]>,
    ) {
        vectorized(
            #[inline(always)]
            || {
                let (k, o) = (self.inputs, self.outputs);
                let dy = &mut dy[..n * o];
                relu_backward(dy, y, dbias);
                let dz = Mat::rows(dy, n, o);
                matmul(dweight, dz.t(), Mat::rows(x, n, k), true);
                if let Some(dx) = dx {
                    matmul(dx, dz, Mat::rows(weight, o, k), false);
                }
            },
        )
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use tch::{Kind, Tensor};

    use super::*;

    fn floats(t: &Tensor) -> Vec<f32> {
        Vec::<f32>::try_from(&t.contiguous().flatten(0, -1)).expect("floats")
    }

    /// Largest absolute difference over the largest magnitude of `b`.
    pub(crate) fn rel_diff(a: &[f32], b: &[f32]) -> f64 {
        assert_eq!(a.len(), b.len());
        let scale = b.iter().fold(0f64, |m, &v| m.max(f64::from(v.abs())));
        let diff = a
            .iter()
            .zip(b)
            .fold(0f64, |m, (&x, &y)| m.max(f64::from((x - y).abs())));
        diff / scale.max(1e-6)
    }

    #[test]
    fn the_strided_convolution_equals_tch_forward_and_backward() {
        let mut rng = SmallRng::seed_from_u64(3);
        for (h, w, n) in [(13, 13, 5), (19, 25, 3), (4, 7, 40), (1, 1, 2)] {
            let conv = StridedConv {
                height: h,
                width: w,
                cin: 16,
                cout: 32,
            };
            let (ho, wo) = conv.out_hw();
            let rand = |rng: &mut SmallRng, len: usize| -> Vec<f32> {
                (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
            };
            // Inputs with exact zeros, as after a ReLU.
            let x: Vec<f32> = rand(&mut rng, n * conv.in_len())
                .into_iter()
                .map(|v| v.max(0.0))
                .collect();
            let weight = rand(&mut rng, 32 * 16 * 9);
            let bias = rand(&mut rng, 32);
            let upstream = rand(&mut rng, n * conv.out_len());

            // tch, NCHW.
            let xt = Tensor::from_slice(&x)
                .view([n as i64, h as i64, w as i64, 16])
                .permute([0, 3, 1, 2])
                .contiguous()
                .set_requires_grad(true);
            let wt = Tensor::from_slice(&weight)
                .view([32, 16, 3, 3])
                .set_requires_grad(true);
            let bt = Tensor::from_slice(&bias).set_requires_grad(true);
            let yt = xt.conv2d(&wt, Some(&bt), [2, 2], [1, 1], [1, 1], 1).relu();
            let ut = Tensor::from_slice(&upstream)
                .view([n as i64, ho as i64, wo as i64, 32])
                .permute([0, 3, 1, 2]);
            (&yt * &ut).sum(Kind::Float).backward();
            let y_ref = floats(&yt.permute([0, 2, 3, 1]));
            let dx_ref = floats(&xt.grad().permute([0, 2, 3, 1]));

            let wm = conv.gemm_weight(&weight);
            let mut scratch = Vec::new();
            let mut y = vec![0f32; n * conv.out_len()];
            conv.forward(&x, n, &wm, &bias, &mut y, &mut scratch);
            let mut dy = upstream.clone();
            let (mut dw, mut db, mut dx) =
                (vec![0f32; wm.len()], vec![0f32; 32], vec![0f32; x.len()]);
            conv.backward(
                &x,
                n,
                &wm,
                &y,
                &mut dy,
                &mut dw,
                &mut db,
                Some(&mut dx),
                &mut scratch,
            );
            let checks = [
                ("output", rel_diff(&y, &y_ref)),
                ("input gradient", rel_diff(&dx, &dx_ref)),
                (
                    "weight gradient",
                    rel_diff(&conv.torch_weight(&dw), &floats(&wt.grad())),
                ),
                ("bias gradient", rel_diff(&db, &floats(&bt.grad()))),
            ];
            for (what, d) in checks {
                assert!(d < 1e-5, "{h}×{w}, batch {n}: {what} differs by {d:e}");
            }
        }
    }

    #[test]
    fn the_first_convolution_equals_tch_over_the_dense_planes() {
        use crate::a2c::input::{BASE_CHANNELS, GoalMarks, NO_GOAL};

        let mut rng = SmallRng::seed_from_u64(4);
        for (w, h, slots, n) in [(13, 13, 0, 4), (25, 19, 2, 3), (5, 4, 1, 6)] {
            let (cells, meta) = crate::a2c::input::random_obs(&mut rng, n, w, h, 0.5);
            let obs = crate::a2c::input::test_view(&cells, &meta, w, h);
            // Goal cells anywhere, one slot in three empty, and (with two
            // slots) some on the agent's cell or on each other.
            let goal_cells: Vec<u32> = (0..n * slots)
                .map(|k| match k % 3 {
                    2 => NO_GOAL,
                    1 if slots == 2 => {
                        meta[k / slots].y as u32 * w as u32 + meta[k / slots].x as u32
                    }
                    _ => rng.random_range(0..(w * h) as u32),
                })
                .collect();
            let goals = (slots > 0).then_some(GoalMarks {
                cells: &goal_cells,
                per_env: slots,
            });
            let mut input = CellInput::new(w, h, slots);
            input.push_obs(&obs, goals);
            let channels = BASE_CHANNELS + slots;
            let conv = FirstConv {
                width: w,
                height: h,
                channels,
                out: 16,
            };
            let rand = |rng: &mut SmallRng, len: usize| -> Vec<f32> {
                (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
            };
            let weight = rand(&mut rng, 16 * channels * 9);
            let bias = rand(&mut rng, 16);
            let upstream = rand(&mut rng, n * conv.out_len());

            let wt = Tensor::from_slice(&weight)
                .view([16, channels as i64, 3, 3])
                .set_requires_grad(true);
            let bt = Tensor::from_slice(&bias).set_requires_grad(true);
            let yt = input
                .to_dense()
                .conv2d(&wt, Some(&bt), [1, 1], [1, 1], [1, 1], 1)
                .relu();
            let ut = Tensor::from_slice(&upstream)
                .view([n as i64, h as i64, w as i64, 16])
                .permute([0, 3, 1, 2]);
            (&yt * &ut).sum(Kind::Float).backward();

            let table = conv.table(&weight);
            let mut y = vec![0f32; n * conv.out_len()];
            conv.forward(&input, 0, n, &table, &bias, &mut y);
            let mut dy = upstream.clone();
            let (mut dt, mut db) = (vec![0f32; table.len()], vec![0f32; 16]);
            conv.backward(&input, 0, n, &y, &mut dy, &mut dt, &mut db);
            let checks = [
                ("output", rel_diff(&y, &floats(&yt.permute([0, 2, 3, 1])))),
                (
                    "weight gradient",
                    rel_diff(&conv.torch_weight(&dt), &floats(&wt.grad())),
                ),
                ("bias gradient", rel_diff(&db, &floats(&bt.grad()))),
            ];
            for (what, d) in checks {
                assert!(
                    d < 1e-5,
                    "{w}×{h}, {slots} goal slots: {what} differs by {d:e}"
                );
            }
        }
    }

    #[test]
    fn the_dense_layer_equals_tch_linear() {
        let mut rng = SmallRng::seed_from_u64(5);
        for (n, k, o) in [(32, 1568, 128), (7, 13, 5), (1920, 64, 128)] {
            let layer = DenseRelu {
                inputs: k,
                outputs: o,
            };
            let rand = |rng: &mut SmallRng, len: usize| -> Vec<f32> {
                (0..len).map(|_| rng.random_range(-1.0..1.0)).collect()
            };
            let x: Vec<f32> = rand(&mut rng, n * k)
                .into_iter()
                .map(|v| v.max(0.0))
                .collect();
            let weight = rand(&mut rng, o * k);
            let bias = rand(&mut rng, o);
            let upstream = rand(&mut rng, n * o);
            let xt = Tensor::from_slice(&x)
                .view([n as i64, k as i64])
                .set_requires_grad(true);
            let wt = Tensor::from_slice(&weight)
                .view([o as i64, k as i64])
                .set_requires_grad(true);
            let bt = Tensor::from_slice(&bias).set_requires_grad(true);
            let yt = xt.linear(&wt, Some(&bt)).relu();
            let ut = Tensor::from_slice(&upstream).view([n as i64, o as i64]);
            (&yt * &ut).sum(Kind::Float).backward();

            let mut y = vec![0f32; n * o];
            let weight_t = crate::a2c::gemm::transposed(&weight, o, k);
            layer.forward(&x, n, &weight_t, &bias, &mut y);
            let mut dy = upstream.clone();
            let (mut dw, mut db, mut dx) = (vec![0f32; o * k], vec![0f32; o], vec![0f32; n * k]);
            layer.backward(&x, n, &weight, &y, &mut dy, &mut dw, &mut db, Some(&mut dx));
            let checks = [
                ("output", rel_diff(&y, &floats(&yt))),
                ("input gradient", rel_diff(&dx, &floats(&xt.grad()))),
                ("weight gradient", rel_diff(&dw, &floats(&wt.grad()))),
                ("bias gradient", rel_diff(&db, &floats(&bt.grad()))),
            ];
            for (what, d) in checks {
                assert!(d < 1e-5, "{n}×{k}→{o}: {what} differs by {d:e}");
            }
        }
    }
}
