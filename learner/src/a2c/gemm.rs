//! One safe matrix product for the own kernels ([`crate::a2c::kernels`]),
//! over the `gemm` crate (Sarah El Kazdadi's, which `candle` uses): its
//! `x86-v4` kernels use AVX-512 where the CPU has it, chosen at run time.
//!
//! Why not libtorch's own `mm`: the x86 libtorch wheels multiply float
//! matrices with MKL, which runs its AVX2 kernels on AMD processors; and
//! why not `matrixmultiply` (the GEMM of `ndarray`): it has AVX2 kernels
//! only. `benches/encoder_kernels.rs` measures all three at the encoder's
//! shapes.
//!
//! The crate's entry point takes raw pointers and strides; [`matmul`]
//! takes slices and checks that every element the strides address lies
//! inside them, so it cannot read or write out of bounds.

// The one `unsafe` call of the learner: see the SAFETY comment in
// `matmul`.
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicUsize, Ordering};

/// Threads of the products (1: the calling thread only).
static THREADS: AtomicUsize = AtomicUsize::new(1);

/// Sets the threads the products use (rayon's global pool when above 1).
pub fn set_threads(threads: usize) {
    THREADS.store(threads.max(1), Ordering::Relaxed);
}

/// Threads the products use.
pub fn threads() -> usize {
    THREADS.load(Ordering::Relaxed)
}

/// A read-only strided view of a float matrix.
#[derive(Debug, Clone, Copy)]
pub struct Mat<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

impl<'a> Mat<'a> {
    /// The row-major `rows × cols` matrix at the start of `data`.
    pub fn rows(data: &'a [f32], rows: usize, cols: usize) -> Mat<'a> {
        Mat {
            data,
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// The transpose (no copy).
    pub fn t(self) -> Mat<'a> {
        Mat {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
            ..self
        }
    }

    /// Elements the view can address: one past the largest offset.
    fn extent(&self) -> usize {
        if self.rows == 0 || self.cols == 0 {
            0
        } else {
            (self.rows - 1) * self.row_stride + (self.cols - 1) * self.col_stride + 1
        }
    }
}

/// `dst = a · b`, or `dst += a · b` with `accumulate`; `dst` is the
/// row-major `a.rows × b.cols` matrix at the start of its slice.
///
/// # Panics
/// When the shapes disagree or a view addresses elements past its slice.
pub fn matmul(dst: &mut [f32], a: Mat<'_>, b: Mat<'_>, accumulate: bool) {
    let (m, k, n) = (a.rows, a.cols, b.cols);
    assert_eq!(b.rows, k, "inner dimensions differ");
    assert!(
        a.extent() <= a.data.len() && b.extent() <= b.data.len() && m * n <= dst.len(),
        "a matrix view reaches past its slice"
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            dst[..m * n].fill(0.0);
        }
        return;
    }
    let parallelism = match threads() {
        1 => gemm::Parallelism::None,
        t => gemm::Parallelism::Rayon(t),
    };
    // SAFETY: `gemm` reads `a` at `i·row_stride + p·col_stride` for
    // `i < m`, `p < k` and `b` likewise for `p < k`, `j < n`, all below the
    // extents asserted to lie within `a.data` and `b.data`; it writes (and
    // with `accumulate` reads) `dst` at `i·n + j < m·n ≤ dst.len()`. `dst`
    // is a unique borrow, so it overlaps neither input. The strides are
    // element counts of slices, so they fit in `isize`.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a.col_stride as isize,
            a.row_stride as isize,
            b.data.as_ptr(),
            b.col_stride as isize,
            b.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// The `cols × rows` transpose of the row-major `rows × cols` matrix `w`
/// (the products run about twice as fast at the learner's shapes with
/// their right operand row-major, so the kernels keep transposed copies of
/// tch's `[out, in]` weights for their forward passes).
pub fn transposed(w: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0f32; rows * cols];
    for (r, row) in w.chunks_exact(cols).take(rows).enumerate() {
        for (c, &v) in row.iter().enumerate() {
            t[c * rows + r] = v;
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook triple loop.
    fn naive(a: Mat<'_>, b: Mat<'_>) -> Vec<f32> {
        let at = |m: &Mat<'_>, i: usize, j: usize| m.data[i * m.row_stride + j * m.col_stride];
        let mut out = vec![0f32; a.rows * b.cols];
        for i in 0..a.rows {
            for j in 0..b.cols {
                out[i * b.cols + j] = (0..a.cols).map(|p| at(&a, i, p) * at(&b, p, j)).sum();
            }
        }
        out
    }

    #[test]
    fn products_of_views_and_transposes_equal_the_triple_loop() {
        let data: Vec<f32> = (0..2000)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) / 25.0)
            .collect();
        for (m, k, n) in [(7, 5, 3), (1, 13, 9), (33, 17, 40), (4, 1, 1)] {
            let a = Mat::rows(&data, m, k);
            let bt = Mat::rows(&data[100..], n, k).t();
            let expected = naive(a, bt);
            let mut dst = vec![1f32; m * n];
            matmul(&mut dst, a, bt, false);
            let close = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(p, q)| (p - q).abs() < 1e-4);
            assert!(close(&dst, &expected), "{m}×{k}×{n}");
            matmul(&mut dst, a, bt, true);
            let doubled: Vec<f32> = expected.iter().map(|v| 2.0 * v).collect();
            assert!(close(&dst, &doubled), "{m}×{k}×{n} accumulated");
        }
    }

    #[test]
    #[should_panic(expected = "reaches past")]
    fn a_view_past_its_slice_is_refused() {
        let data = vec![0f32; 10];
        let mut dst = vec![0f32; 16];
        matmul(
            &mut dst,
            Mat::rows(&data, 4, 3),
            Mat::rows(&data, 3, 4),
            false,
        );
    }
}
