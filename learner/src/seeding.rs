//! Determinism with libtorch's process-global generator.
//!
//! libtorch draws weight initialisations (and `rand_like`, `multinomial`)
//! from one generator shared by every thread of the process, and tch does
//! not expose per-call generators. Two models built at the same time on two
//! threads (parallel tests, or a learner that owns a latent model and `π_g`)
//! would interleave their draws, so the same seed could give different
//! weights. This crate therefore keeps the global generator to weight
//! initialisation only, under one lock ([`init_seeded`]), and draws every
//! training-time random number (HardKuma noise, sampled actions) from a
//! [`SmallRng`](rand::rngs::SmallRng) owned by the model that uses it ([`uniform_like`],
//! [`sample_categorical`]).
//!
//! Tests follow the same rule: libtest runs them on parallel threads of one
//! process, so a test that draws random weights or `randn` inputs outside
//! [`init_seeded`] can shift another test's seeded initialisation and make a
//! determinism test fail at random.

use std::sync::Mutex;

use rand::Rng;
use tch::{Kind, Tensor};

/// Serialises `manual_seed` + initialisation across threads.
static TORCH_GENERATOR: Mutex<()> = Mutex::new(());

/// Runs `init` (which builds networks) with libtorch's generator seeded by
/// `seed`, holding a process-wide lock so no other thread draws in between.
pub fn init_seeded<T>(seed: u64, init: impl FnOnce() -> T) -> T {
    // A panic while holding the lock leaves no broken state behind: the
    // next caller reseeds anyway.
    let _guard = TORCH_GENERATOR
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    tch::manual_seed(seed as i64);
    init()
}

/// A tensor shaped and typed like `like`, filled with independent draws from
/// `U(low, high)` taken from `rng`.
pub fn uniform_like(rng: &mut impl Rng, like: &Tensor, low: f64, high: f64) -> Tensor {
    let n = like.numel();
    let values: Vec<f64> = (0..n).map(|_| rng.random_range(low..high)).collect();
    Tensor::from_slice(&values)
        .view(like.size().as_slice())
        .to_kind(like.kind())
        .to_device(like.device())
}

/// One draw per row of `probs` (`[B, A]` rows of probabilities) by inverse
/// CDF with `rng`, or each row's argmax when `greedy`.
pub fn sample_categorical(rng: &mut impl Rng, probs: &Tensor, greedy: bool) -> Vec<u8> {
    let num_actions = probs.size()[1] as usize;
    let flat: Vec<f32> = tch::no_grad(|| Vec::try_from(probs.to_kind(Kind::Float).flatten(0, -1)))
        .expect("invariant: probabilities convert to a float vector");
    flat.chunks_exact(num_actions)
        .map(|p| {
            let chosen = if greedy {
                most_likely(p)
            } else {
                let u: f32 = rng.random();
                let mut cumulative = 0.0;
                p.iter()
                    .position(|&q| {
                        cumulative += q;
                        u < cumulative
                    })
                    .unwrap_or(num_actions - 1)
            };
            chosen as u8
        })
        .collect()
}

/// One draw per row of `probs` (`[B, A]`) by inverse CDF with `rng`, as
/// an index (for choice sets larger than 256: a Manager's subgoal cells).
pub fn sample_index(rng: &mut impl Rng, probs: &Tensor) -> Vec<usize> {
    let width = probs.size()[1] as usize;
    let flat: Vec<f32> =
        tch::no_grad(|| Vec::try_from(probs.to_kind(Kind::Float).contiguous().flatten(0, -1)))
            .expect("invariant: probabilities convert to a float vector");
    sample_rows(rng, &flat, width)
}

/// [`sample_index`] of probabilities as floats: one draw per `width`-wide
/// row of `flat`.
pub fn sample_rows(rng: &mut impl Rng, flat: &[f32], width: usize) -> Vec<usize> {
    choose_rows(rng, flat, width, false)
}

/// [`sample_rows`], or each row's most likely choice when `greedy` (the
/// first of equals; masked choices have probability 0 and are never the
/// most likely unless the whole row is masked). Greedy takes nothing from
/// `rng`.
pub fn choose_rows(rng: &mut impl Rng, flat: &[f32], width: usize, greedy: bool) -> Vec<usize> {
    if greedy {
        return flat.chunks_exact(width).map(most_likely).collect();
    }
    flat.chunks_exact(width)
        .map(|p| {
            let u: f32 = rng.random();
            let mut cumulative = 0.0;
            // The last choice with non-zero probability takes any rounding
            // remainder (never a masked one).
            let last = p.iter().rposition(|&q| q > 0.0).unwrap_or(width - 1);
            p.iter()
                .position(|&q| {
                    cumulative += q;
                    q > 0.0 && u < cumulative
                })
                .unwrap_or(last)
        })
        .collect()
}

/// The index of a row's largest probability (the first of equals).
fn most_likely(p: &[f32]) -> usize {
    p.iter()
        .enumerate()
        .fold(0, |best, (a, &q)| if q > p[best] { a } else { best })
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand::rngs::SmallRng;

    use super::*;

    #[test]
    fn greedy_rows_take_each_rows_most_likely_choice_and_no_draw() {
        // Rows of 4; a masked choice has probability 0.
        let flat = [0.1, 0.6, 0.3, 0.0, 0.0, 0.2, 0.2, 0.6, 0.5, 0.0, 0.5, 0.0];
        let mut rng = SmallRng::seed_from_u64(5);
        let before = rng.clone().random::<u64>();
        assert_eq!(choose_rows(&mut rng, &flat, 4, true), vec![1, 3, 0]);
        assert_eq!(rng.random::<u64>(), before, "greedy drew from the RNG");
        let sampled: Vec<Vec<usize>> = (0..200)
            .map(|_| choose_rows(&mut rng, &flat, 4, false))
            .collect();
        assert!(
            sampled
                .iter()
                .all(|r| r[0] != 3 && r[1] != 0 && r[2] % 2 == 0)
        );
        assert!(
            sampled.iter().any(|r| r[0] != 1),
            "sampling took the mode alone"
        );
    }

    #[test]
    fn initialisation_is_repeatable_under_concurrent_draws() {
        let init = || init_seeded(7, || Tensor::randn([64], (Kind::Float, tch::Device::Cpu)));
        let reference = init();
        // Another thread hammers the global generator meanwhile.
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let noisy = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                    let _ =
                        init_seeded(99, || Tensor::randn([64], (Kind::Float, tch::Device::Cpu)));
                }
            })
        };
        for _ in 0..200 {
            assert!(init().equal(&reference));
        }
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        noisy.join().expect("noise thread");
    }

    #[test]
    fn uniform_noise_has_the_shape_kind_and_range_and_repeats_per_seed() {
        let like = Tensor::zeros([3, 5], (Kind::Double, tch::Device::Cpu));
        let draw = |seed| uniform_like(&mut SmallRng::seed_from_u64(seed), &like, 0.25, 0.5);
        let u = draw(1);
        assert_eq!(u.size(), vec![3, 5]);
        assert_eq!(u.kind(), Kind::Double);
        assert!(u.min().double_value(&[]) >= 0.25 && u.max().double_value(&[]) < 0.5);
        assert!(u.equal(&draw(1)));
        assert!(!u.equal(&draw(2)));
    }

    #[test]
    fn categorical_draws_follow_the_probabilities() {
        let probs = Tensor::from_slice(&[0.1_f32, 0.0, 0.9, 1.0, 0.0, 0.0]).view([2, 3]);
        let mut rng = SmallRng::seed_from_u64(3);
        let mut counts = [[0_u32; 3]; 2];
        for _ in 0..10_000 {
            for (row, a) in sample_categorical(&mut rng, &probs, false)
                .into_iter()
                .enumerate()
            {
                counts[row][a as usize] += 1;
            }
        }
        assert_eq!(counts[0][1], 0, "zero-probability action never drawn");
        assert!((800..1200).contains(&counts[0][0]), "{counts:?}");
        assert_eq!(counts[1][0], 10_000);
        assert_eq!(sample_categorical(&mut rng, &probs, true), vec![2, 0]);
    }
}
