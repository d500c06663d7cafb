//! The encoder's stride-2 convolution (16 → 32 channels, 3×3, padding 1,
//! then ReLU), forward and backward (input, weight and bias gradients), in
//! libtorch (NCHW and channels-last) and in the project's own kernel
//! (`learner::a2c::kernels::StridedConv`), timed in alternating windows in
//! one process: `cargo bench -p learner --bench encoder_kernels [-- SECONDS
//! [THREADS]]`. Prints GFLOP/s (forward + backward = 3 × the forward's
//! multiply-adds × 2) and the ratios; before that the GEMMs of the encoder
//! in three libraries, after it the encoder past its first layer over a
//! whole rollout, and the LSTM core with its heads over a rollout (tch's
//! `lstm_cell` with autograd against [`learner::a2c::lstm`]). It asserts
//! nothing; the kernels' equality with tch is tested in `a2c::kernels` and
//! `a2c::lstm`.

use std::time::Instant;

use learner::a2c::kernels::{DenseRelu, StridedConv};
use learner::a2c::lstm::{Heads, LstmCell, StepActivations, transposed};
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
    let wf_own_t = learner::a2c::gemm::transposed(&wf_own, 128, fc.inputs);
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
                    &wf_own_t,
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

/// The LSTM core (128 → 128) and the heads (3 actions, a value) over a
/// rollout of `steps` steps of `batch` rows, the state reset for some rows
/// between steps, forward and backward through time: tch's `lstm_cell`
/// and `linear` with autograd, one backward over all steps; the own
/// kernels ([`learner::a2c::lstm`]) whole, and their parts alone (the
/// forward steps, the backward steps, the rollout's weight GEMMs; the
/// heads' backward is the rest).
fn core_rollout(steps: usize, batch: usize, seconds: f64) {
    let (input, hidden, actions) = (128usize, 128usize, 3usize);
    let (n, rows, g4) = (batch, steps * batch, 4 * hidden);
    let opts = (Kind::Float, Device::Cpu);
    let floats = |t: &Tensor| Vec::<f32>::try_from(&t.flatten(0, -1)).expect("floats");
    let leaf = |shape: &[i64]| (Tensor::randn(shape, opts) * 0.1).set_requires_grad(true);
    let (gi, hi, ai) = (g4 as i64, hidden as i64, actions as i64);
    let (w_ih, w_hh) = (leaf(&[gi, input as i64]), leaf(&[gi, hi]));
    let (b_ih, b_hh) = (leaf(&[gi]), leaf(&[gi]));
    let (w_pi, b_pi, w_v, b_v) = (leaf(&[ai, hi]), leaf(&[ai]), leaf(&[1, hi]), leaf(&[1]));
    let xs = Tensor::randn([steps as i64, n as i64, input as i64], opts).relu();
    let x_leaf = xs.copy().set_requires_grad(true);
    let keep: Vec<f32> = (0..rows)
        .map(|k| if k % 17 == 0 { 0.0 } else { 1.0 })
        .collect();
    let keep_t = Tensor::from_slice(&keep).view([steps as i64, n as i64, 1]);
    let dl = Tensor::randn([steps as i64, n as i64, ai], opts);
    let dv = Tensor::randn([steps as i64, n as i64], opts);

    let cell = LstmCell { input, hidden };
    let heads = Heads { hidden, actions };
    let (ow_ih, ow_hh) = (floats(&w_ih.detach()), floats(&w_hh.detach()));
    let bias = floats(&(&b_ih + &b_hh).detach());
    let (ow_pi, ob_pi) = (floats(&w_pi.detach()), floats(&b_pi.detach()));
    let (ow_ih_t, ow_hh_t) = (
        transposed(&ow_ih, g4, input),
        transposed(&ow_hh, g4, hidden),
    );
    let ow_pi_t = transposed(&ow_pi, actions, hidden);
    let (ow_v, ob_v) = (floats(&w_v.detach()), floats(&b_v.detach())[0]);
    let (ox, odl, odv) = (floats(&xs), floats(&dl), floats(&dv));

    /// The activations of a rollout.
    struct Acts {
        h_in: Vec<f32>,
        c_in: Vec<f32>,
        gates: Vec<f32>,
        tanh_c: Vec<f32>,
        h_out: Vec<f32>,
        c: Vec<f32>,
        logits: Vec<f32>,
        values: Vec<f32>,
    }
    let new_acts = || Acts {
        h_in: vec![0f32; rows * hidden],
        c_in: vec![0f32; rows * hidden],
        gates: vec![0f32; rows * g4],
        tanh_c: vec![0f32; rows * hidden],
        h_out: vec![0f32; rows * hidden],
        c: vec![0f32; n * hidden],
        logits: vec![0f32; rows * actions],
        values: vec![0f32; rows],
    };
    let forward = |a: &mut Acts| {
        a.c.fill(0.0);
        for t in 0..steps {
            let (s, m) = (t * n * hidden, n * hidden);
            for r in 0..m {
                let k = if t == 0 {
                    0.0
                } else {
                    keep[t * n + r / hidden]
                };
                a.h_in[s + r] = if t == 0 { 0.0 } else { a.h_out[s - m + r] * k };
                a.c_in[s + r] = a.c[r] * k;
            }
            cell.forward(
                &ox[t * n * input..],
                &a.h_in[s..][..m],
                &a.c_in[s..][..m],
                n,
                &ow_ih_t,
                &ow_hh_t,
                &bias,
                &mut a.gates[t * n * g4..],
                &mut a.c,
                &mut a.tanh_c[s..],
                &mut a.h_out[s..],
            );
            heads.forward(
                &a.h_out[s..],
                n,
                &ow_pi_t,
                &ob_pi,
                &ow_v,
                ob_v,
                &mut a.logits[t * n * actions..],
                &mut a.values[t * n..],
            );
        }
    };
    let mut acts = new_acts();
    forward(&mut acts);
    let acts = acts;
    let heads_backward = || {
        let (mut dw_pi, mut db_pi) = (vec![0f32; ow_pi.len()], vec![0f32; actions]);
        let (mut dw_v, mut db_v) = (vec![0f32; hidden], 0f32);
        let mut dh_all = vec![0f32; rows * hidden];
        heads.backward(
            &acts.h_out,
            rows,
            &ow_pi,
            &ow_v,
            &odl,
            &odv,
            &mut dw_pi,
            &mut db_pi,
            &mut dw_v,
            &mut db_v,
            &mut dh_all,
        );
        dh_all
    };
    let through_time = |dh_all: &[f32]| {
        let m = n * hidden;
        let mut dz = vec![0f32; rows * g4];
        let (mut dh, mut dc, mut dh_in) = (vec![0f32; m], vec![0f32; m], vec![0f32; m]);
        for t in (0..steps).rev() {
            let s = t * m;
            for (d, g) in dh.iter_mut().zip(&dh_all[s..][..m]) {
                *d += g;
            }
            let act = StepActivations {
                gates: &acts.gates[t * n * g4..][..n * g4],
                c_in: &acts.c_in[s..][..m],
                tanh_c: &acts.tanh_c[s..][..m],
            };
            cell.backward_step(
                &act,
                n,
                &ow_hh,
                &dh,
                &mut dc,
                &mut dz[t * n * g4..],
                &mut dh_in,
            );
            for r in 0..m {
                let k = keep[t * n + r / hidden];
                dh[r] = dh_in[r] * k;
                dc[r] *= k;
            }
        }
        dz
    };
    let weights = |dz: &[f32]| {
        let (mut dw_ih, mut dw_hh) = (vec![0f32; ow_ih.len()], vec![0f32; ow_hh.len()]);
        let (mut db, mut dx) = (vec![0f32; g4], vec![0f32; rows * input]);
        cell.weight_gradients(
            dz, &ox, &acts.h_in, rows, &ow_ih, &mut dw_ih, &mut dw_hh, &mut db, &mut dx,
        );
        std::hint::black_box((dw_ih, dw_hh, db, dx));
    };
    let dh_all = heads_backward();
    let dz = through_time(&dh_all);
    let tch_run = || {
        let zeros = || Tensor::zeros([n as i64, hi], opts);
        let (mut h, mut c) = (zeros(), zeros());
        let mut terms = Vec::with_capacity(steps);
        for t in 0..steps as i64 {
            let k = keep_t.get(t);
            let (hn, cn) = x_leaf.get(t).lstm_cell(
                &[&(&h * &k), &(&c * &k)],
                &w_ih,
                &w_hh,
                Some(&b_ih),
                Some(&b_hh),
            );
            let lg = hn.linear(&w_pi, Some(&b_pi));
            let v = hn.linear(&w_v, Some(&b_v)).squeeze_dim(-1);
            terms.push((lg * dl.get(t)).sum(Kind::Float) + (v * dv.get(t)).sum(Kind::Float));
            h = hn;
            c = cn;
        }
        let loss = Tensor::stack(&terms, 0).sum(Kind::Float);
        let leaves = [
            &w_ih, &w_hh, &b_ih, &b_hh, &w_pi, &b_pi, &w_v, &b_v, &x_leaf,
        ];
        std::hint::black_box(Tensor::run_backward(&[loss], &leaves, false, false));
    };
    let (mut scratch, mut scratch2) = (new_acts(), new_acts());
    let mut runs: Vec<Run<'_>> = vec![
        Box::new(tch_run),
        Box::new(|| {
            forward(&mut scratch);
            weights(&through_time(&heads_backward()));
        }),
        Box::new(|| forward(&mut scratch2)),
        Box::new(|| std::mem::drop(through_time(&dh_all))),
        Box::new(|| weights(&dz)),
        Box::new(|| std::mem::drop(heads_backward())),
    ];
    let ms: Vec<f64> = alternate(&mut runs, seconds)
        .into_iter()
        .map(|r| 1e3 / r)
        .collect();
    println!(
        "{:>8} {:>10.2} {:>10.2} {:>10.2} {:>10.2} {:>10.2} {:>10.2} {:>9.2}×",
        format!("{steps}×{batch}"),
        ms[0],
        ms[1],
        ms[2],
        ms[3],
        ms[4],
        ms[5],
        ms[0] / ms[1]
    );
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
    if args.get(2).map(String::as_str) == Some("core") {
        print_core_table(seconds);
        return;
    }
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
    print_core_table(seconds);
}

/// The LSTM core's table ([`core_rollout`]).
fn print_core_table(seconds: f64) {
    println!(
        "\nLSTM core 128 → 128 + heads over a rollout, forward and backward through time, ms per rollout"
    );
    println!(
        "{:>8} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "T×B", "tch", "own", "own fwd", "own bptt", "own dW", "own heads", "tch/own"
    );
    core_rollout(60, 32, seconds);
}
