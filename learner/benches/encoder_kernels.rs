//! The encoder's stride-2 convolution (16 → 32 channels, 3×3, padding 1,
//! then ReLU), forward and backward (input, weight and bias gradients), in
//! libtorch (NCHW and channels-last) and in the project's own kernel
//! (`learner::a2c::kernels::StridedConv`), timed in alternating windows in
//! one process: `cargo bench -p learner --bench encoder_kernels [-- SECONDS
//! [THREADS]]`. Prints GFLOP/s (forward + backward = 3 × the forward's
//! multiply-adds × 2) and the ratios; before that the GEMMs of the encoder
//! in three libraries, after it the encoder past its first layer over a
//! whole rollout. It asserts nothing; the kernels' equality with tch is
//! tested in `a2c::kernels`.

use std::time::Instant;

use learner::a2c::kernels::{DenseRelu, StridedConv};
use tch::{Device, Kind, Tensor};

/// One way to run the convolution's forward and backward once.
type Run<'a> = Box<dyn FnMut() + 'a>;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// An NCHW-shaped tensor with channels-last strides (how PyTorch's
/// `memory_format=torch.channels_last` lays it out; tch 0.26 has no
/// memory-format argument): `[N, H, W, C]` storage, permuted.
fn channels_last(nhwc: &Tensor) -> Tensor {
    nhwc.permute([0, 3, 1, 2])
}

/// Times `runs` in `rounds` alternating windows over `seconds`: the
/// median calls per second of each.
fn alternate(runs: &mut [Run<'_>], seconds: f64) -> Vec<f64> {
    for r in runs.iter_mut() {
        r();
    }
    const ROUNDS: usize = 5;
    let window = seconds / (ROUNDS * runs.len()) as f64;
    let mut rates = vec![Vec::new(); runs.len()];
    for _ in 0..ROUNDS {
        for (k, r) in runs.iter_mut().enumerate() {
            let start = Instant::now();
            let mut count = 0u64;
            while start.elapsed().as_secs_f64() < window {
                r();
                count += 1;
            }
            rates[k].push(count as f64 / start.elapsed().as_secs_f64());
        }
    }
    rates.into_iter().map(median).collect()
}

/// The encoder after its first layer (stride-2 convolution, ReLU, flatten,
/// fully connected 32·h'·w' → 128, ReLU) over a rollout of `steps` steps of
/// `batch` environments, as the learner runs it: tch keeps every step's
/// graph and back-propagates through all of them once; the own kernels run
/// each step's forward and one backward over all `steps · batch` rows.
fn rollout_tail(name: &str, h: usize, w: usize, steps: usize, batch: usize, seconds: f64) {
    let conv = StridedConv {
        height: h,
        width: w,
        cin: 16,
        cout: 32,
    };
    let fc = DenseRelu {
        inputs: conv.out_len(),
        outputs: 128,
    };
    let n = steps * batch;
    let opts = (Kind::Float, Device::Cpu);
    let x_nhwc = (Tensor::rand([n as i64, h as i64, w as i64, 16], opts) - 0.3).relu();
    let w2 = (Tensor::randn([32, 16, 3, 3], opts) * 0.1).set_requires_grad(true);
    let b2 = (Tensor::randn([32], opts) * 0.1).set_requires_grad(true);
    let wf = (Tensor::randn([128, fc.inputs as i64], opts) * 0.02).set_requires_grad(true);
    let bf = (Tensor::randn([128], opts) * 0.1).set_requires_grad(true);
    let up = Tensor::randn([n as i64, 128], opts);
    let floats =
        |t: &Tensor| Vec::<f32>::try_from(&t.detach().contiguous().flatten(0, -1)).expect("floats");
    // tch: per-step leaves in the layout the fast path hands to conv2
    // (channels-last strides) and in NCHW.
    let leaves = |cl: bool| -> Vec<Tensor> {
        (0..steps as i64)
            .map(|t| {
                let x = x_nhwc.narrow(0, t * batch as i64, batch as i64);
                let x = if cl {
                    channels_last(&x.copy())
                } else {
                    x.permute([0, 3, 1, 2]).contiguous()
                };
                x.set_requires_grad(true)
            })
            .collect()
    };
    let (xs_cl, xs_nchw) = (leaves(true), leaves(false));
    let tch_run = |xs: &[Tensor]| {
        let mut terms = Vec::with_capacity(xs.len());
        for (t, x) in xs.iter().enumerate() {
            let f = x
                .conv2d(&w2, Some(&b2), [2, 2], [1, 1], [1, 1], 1)
                .relu()
                .flatten(1, -1)
                .linear(&wf, Some(&bf))
                .relu();
            terms.push((f * up.narrow(0, (t * batch) as i64, batch as i64)).sum(Kind::Float));
        }
        let loss = Tensor::stack(&terms, 0).sum(Kind::Float);
        let mut inputs: Vec<&Tensor> = xs.iter().collect();
        inputs.extend([&w2, &b2, &wf, &bf]);
        std::hint::black_box(Tensor::run_backward(&[loss], &inputs, false, false));
    };
    let x_own = floats(&x_nhwc);
    let (w2_own, b2_own) = (conv.gemm_weight(&floats(&w2)), floats(&b2));
    let (wf_own, bf_own) = (floats(&wf), floats(&bf));
    let up_own = floats(&up);
    let mut y2 = vec![0f32; n * conv.out_len()];
    let mut f = vec![0f32; n * 128];
    let mut df = vec![0f32; n * 128];
    let mut dy2 = vec![0f32; n * conv.out_len()];
    let mut dx = vec![0f32; x_own.len()];
    let (mut dw2, mut db2) = (vec![0f32; w2_own.len()], vec![0f32; 32]);
    let (mut dwf, mut dbf) = (vec![0f32; wf_own.len()], vec![0f32; 128]);
    let mut scratch = Vec::new();
    let mut runs: Vec<Run<'_>> = vec![
        Box::new(|| tch_run(&xs_nchw)),
        Box::new(|| tch_run(&xs_cl)),
        Box::new(|| {
            for t in 0..steps {
                let r = t * batch;
                conv.forward(
                    &x_own[r * conv.in_len()..],
                    batch,
                    &w2_own,
                    &b2_own,
                    &mut y2[r * conv.out_len()..],
                    &mut scratch,
                );
                fc.forward(
                    &y2[r * fc.inputs..],
                    batch,
                    &wf_own,
                    &bf_own,
                    &mut f[r * 128..],
                );
            }
            df.copy_from_slice(&up_own);
            for g in [&mut dw2, &mut db2, &mut dwf, &mut dbf, &mut dx] {
                g.fill(0.0);
            }
            fc.backward(
                &y2,
                n,
                &wf_own,
                &f,
                &mut df,
                &mut dwf,
                &mut dbf,
                Some(&mut dy2),
            );
            conv.backward(
                &x_own,
                n,
                &w2_own,
                &y2,
                &mut dy2,
                &mut dw2,
                &mut db2,
                Some(&mut dx),
                &mut scratch,
            );
            std::hint::black_box((&dx, &dw2, &dwf));
        }),
    ];
    let rates = alternate(&mut runs, seconds);
    let ms: Vec<f64> = rates.iter().map(|r| 1e3 / r).collect();
    println!(
        "{:<14} {:>6} {:>12.1} {:>12.1} {:>12.1} {:>9.2}× {:>9.2}×",
        name,
        format!("{steps}×{batch}"),
        ms[0],
        ms[1],
        ms[2],
        ms[0] / ms[2],
        ms[1] / ms[2],
    );
}

/// The GEMMs of the encoder at batch 32 and over a rollout of 1920 rows, in
/// the three libraries at hand: GFLOP/s of each.
fn gemm_table(seconds: f64) {
    use learner::a2c::gemm::{Mat, matmul};
    println!(
        "\nGEMM at the encoder's shapes (m×k×n), GFLOP/s: ndarray's matrixmultiply, the gemm crate, tch mm (MKL)"
    );
    println!(
        "{:<26} {:>18} {:>14} {:>10} {:>10} {:>10}",
        "product", "m×k×n", "matrixmultiply", "gemm", "tch mm", "gemm/mm"
    );
    let shapes = [
        ("conv2 forward, batch 32", 32 * 49, 144, 32),
        ("conv2 dW, rollout", 144, 1920 * 49, 32),
        ("fc forward, batch 32", 32, 1568, 128),
        ("fc dW, rollout", 128, 1920, 1568),
        ("fc dX, rollout", 1920, 128, 1568),
        ("LSTM gates, batch 32", 32, 128, 512),
    ];
    for (name, m, k, n) in shapes {
        let a: Vec<f32> = (0..m * k).map(|i| (i % 7) as f32 * 0.1).collect();
        let b: Vec<f32> = (0..k * n).map(|i| (i % 5) as f32 * 0.1).collect();
        let mut c = vec![0f32; m * n];
        let (at, bt) = (
            Tensor::from_slice(&a).view([m as i64, k as i64]),
            Tensor::from_slice(&b).view([k as i64, n as i64]),
        );
        let an = ndarray::ArrayView2::from_shape((m, k), &a).expect("shape");
        let bn = ndarray::ArrayView2::from_shape((k, n), &b).expect("shape");
        let mut cn = ndarray::Array2::<f32>::zeros((m, n));
        let mut runs: Vec<Run<'_>> = vec![
            Box::new(|| ndarray::linalg::general_mat_mul(1.0, &an, &bn, 0.0, &mut cn)),
            Box::new(|| matmul(&mut c, Mat::rows(&a, m, k), Mat::rows(&b, k, n), false)),
            Box::new(|| {
                let _ = std::hint::black_box(at.mm(&bt));
            }),
        ];
        let rates = alternate(&mut runs, seconds / 4.0);
        let g: Vec<f64> = rates
            .iter()
            .map(|r| r * 2.0 * (m * k * n) as f64 / 1e9)
            .collect();
        println!(
            "{:<26} {:>18} {:>14.1} {:>10.1} {:>10.1} {:>9.2}×",
            name,
            format!("{m}×{k}×{n}"),
            g[0],
            g[1],
            g[2],
            g[1] / g[2]
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let seconds: f64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(8.0);
    let threads: i32 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1);
    tch::set_num_threads(threads);
    learner::a2c::gemm::set_threads(threads as usize);
    tch::manual_seed(0);
    gemm_table(seconds);
    println!();
    let shapes = [("small 13×13", 13, 13), ("medium 25×19", 19, 25)];
    let batches = [32usize, 1920];
    println!(
        "stride-2 conv 16→32 + ReLU, forward+backward, {threads} libtorch thread(s), \
         {seconds} s per shape and batch in alternating windows"
    );
    println!(
        "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10} {:>10} {:>10}",
        "maze", "batch", "tch NCHW", "tch ch-last", "own", "own/NCHW", "own/ch-l", "ch-l/NCHW"
    );
    for (name, h, w) in shapes {
        for n in batches {
            let conv = StridedConv {
                height: h,
                width: w,
                cin: 16,
                cout: 32,
            };
            let (ho, wo) = conv.out_hw();
            let opts = (Kind::Float, Device::Cpu);
            let x_nhwc = Tensor::rand([n as i64, h as i64, w as i64, 16], opts) - 0.3;
            let x_nhwc = x_nhwc.relu();
            let weight = Tensor::randn([32, 16, 3, 3], opts) * 0.1;
            let bias = Tensor::randn([32], opts) * 0.1;
            let up_nhwc = Tensor::randn([n as i64, ho as i64, wo as i64, 32], opts);

            // tch, NCHW.
            let x_nchw = x_nhwc
                .permute([0, 3, 1, 2])
                .contiguous()
                .set_requires_grad(true);
            let up_nchw = up_nhwc.permute([0, 3, 1, 2]).contiguous();
            let w_t = weight.copy().set_requires_grad(true);
            let b_t = bias.copy().set_requires_grad(true);
            // tch, channels-last input, weight and upstream gradient.
            let x_cl = channels_last(&x_nhwc.copy()).set_requires_grad(true);
            let up_cl = channels_last(&up_nhwc);
            let w_cl_leaf = weight
                .permute([0, 2, 3, 1])
                .contiguous()
                .set_requires_grad(true);
            let b_cl = bias.copy().set_requires_grad(true);

            let tch_run =
                |x: &Tensor, wt: &Tensor, b: &Tensor, up: &Tensor, leaves: [&Tensor; 3]| {
                    let y = x.conv2d(wt, Some(b), [2, 2], [1, 1], [1, 1], 1).relu();
                    let loss = (&y * up).sum(Kind::Float);
                    let grads = Tensor::run_backward(&[loss], &leaves, false, false);
                    std::hint::black_box(grads);
                };
            // Own kernel.
            let x_own = Vec::<f32>::try_from(&x_nhwc.flatten(0, -1)).expect("floats");
            let up_own = Vec::<f32>::try_from(&up_nhwc.flatten(0, -1)).expect("floats");
            let wm =
                conv.gemm_weight(&Vec::<f32>::try_from(&weight.flatten(0, -1)).expect("floats"));
            let b_own = Vec::<f32>::try_from(&bias).expect("floats");
            let mut y_own = vec![0f32; n * conv.out_len()];
            let mut dy = vec![0f32; n * conv.out_len()];
            let mut dx = vec![0f32; x_own.len()];
            let (mut dw, mut db) = (vec![0f32; wm.len()], vec![0f32; 32]);
            let mut scratch = Vec::new();

            let mut runs: Vec<Run<'_>> = vec![
                Box::new(|| tch_run(&x_nchw, &w_t, &b_t, &up_nchw, [&x_nchw, &w_t, &b_t])),
                Box::new(|| {
                    let wt = w_cl_leaf.permute([0, 3, 1, 2]);
                    tch_run(&x_cl, &wt, &b_cl, &up_cl, [&x_cl, &w_cl_leaf, &b_cl])
                }),
                Box::new(|| {
                    conv.forward(&x_own, n, &wm, &b_own, &mut y_own, &mut scratch);
                    dy.copy_from_slice(&up_own);
                    dx.fill(0.0);
                    dw.fill(0.0);
                    db.fill(0.0);
                    conv.backward(
                        &x_own,
                        n,
                        &wm,
                        &y_own,
                        &mut dy,
                        &mut dw,
                        &mut db,
                        Some(&mut dx),
                        &mut scratch,
                    );
                    std::hint::black_box((&dx, &dw, &db));
                }),
            ];
            let y_cl = x_cl.conv2d(
                &w_cl_leaf.permute([0, 3, 1, 2]),
                Some(&b_cl),
                [2, 2],
                [1, 1],
                [1, 1],
                1,
            );
            assert_eq!(
                y_cl.stride()[1],
                1,
                "the channels-last variant computes in channels-last (output strides {:?})",
                y_cl.stride()
            );
            let rates = alternate(&mut runs, seconds);
            let flops = 6.0 * (conv.macs() * n) as f64;
            let g: Vec<f64> = rates.into_iter().map(|r| r * flops / 1e9).collect();
            println!(
                "{:<14} {:>6} {:>12.1} {:>12.1} {:>12.1} {:>9.2}× {:>9.2}× {:>9.2}×",
                name,
                n,
                g[0],
                g[1],
                g[2],
                g[2] / g[0],
                g[2] / g[1],
                g[1] / g[0]
            );
        }
    }
    println!(
        "\nencoder after the first layer (conv2 + ReLU + fc 128 + ReLU) over a rollout, forward and backward, ms per rollout"
    );
    println!(
        "{:<14} {:>6} {:>12} {:>12} {:>12} {:>10} {:>10}",
        "maze", "T×B", "tch NCHW", "tch ch-last", "own", "NCHW/own", "ch-l/own"
    );
    for (name, h, w) in shapes {
        rollout_tail(name, h, w, 60, 32, seconds);
    }
}
