//! A random number generator whose state can be saved and restored: a
//! training run checkpoints its environments mid-episode (so that
//! validation and a resume after a crash leave the training stream
//! untouched), and rand's `SmallRng` does not serialise.
//!
//! [`ReplayRng`] is `SmallRng` seeded from a `u64` that counts the words it
//! has drawn; its [`RngState`] is `(seed, draws)`, and restoring re-seeds and
//! discards `draws` words. Every `next_u32` and `next_u64` of `SmallRng`
//! advances its state by one step, so the restored generator continues the
//! very same stream, and the stream is the one `SmallRng::seed_from_u64`
//! gives (results made before it existed stay reproducible).

use rand::rngs::SmallRng;
use rand::{RngCore, SeedableRng};
use serde::{Deserialize, Serialize};

/// The saved state of a [`ReplayRng`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RngState {
    /// The seed it started from.
    pub seed: u64,
    /// Words drawn since.
    pub draws: u64,
}

/// `SmallRng` with a restorable state (module docs).
#[derive(Debug, Clone)]
pub struct ReplayRng {
    inner: SmallRng,
    seed: u64,
    draws: u64,
}

impl ReplayRng {
    /// The generator `SmallRng::seed_from_u64(seed)` would be.
    pub fn seed_from_u64(seed: u64) -> ReplayRng {
        ReplayRng {
            inner: SmallRng::seed_from_u64(seed),
            seed,
            draws: 0,
        }
    }

    /// Its state now.
    pub fn state(&self) -> RngState {
        RngState {
            seed: self.seed,
            draws: self.draws,
        }
    }

    /// The generator in `state`: re-seeded, `state.draws` words discarded.
    pub fn from_state(state: RngState) -> ReplayRng {
        let mut rng = ReplayRng::seed_from_u64(state.seed);
        for _ in 0..state.draws {
            rng.inner.next_u64();
        }
        rng.draws = state.draws;
        rng
    }
}

impl RngCore for ReplayRng {
    fn next_u32(&mut self) -> u32 {
        self.draws += 1;
        self.inner.next_u32()
    }
    fn next_u64(&mut self) -> u64 {
        self.draws += 1;
        self.inner.next_u64()
    }
    fn fill_bytes(&mut self, dest: &mut [u8]) {
        rand::rand_core::impls::fill_bytes_via_next(self, dest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn the_stream_is_small_rngs_and_a_restored_generator_continues_it() {
        let mut small = SmallRng::seed_from_u64(7);
        let mut replay = ReplayRng::seed_from_u64(7);
        let mut saved = None;
        for i in 0..1000 {
            if i == 400 {
                saved = Some(replay.state());
            }
            match i % 3 {
                0 => assert_eq!(small.random_range(0..97u32), replay.random_range(0..97u32)),
                1 => assert_eq!(small.random::<f32>(), replay.random::<f32>()),
                _ => assert_eq!(small.next_u64(), replay.next_u64()),
            }
        }
        let mut a = ReplayRng::from_state(saved.expect("saved"));
        let mut b = ReplayRng::seed_from_u64(7);
        let skip: Vec<u64> = (0..400)
            .map(|i| match i % 3 {
                0 => u64::from(b.random_range(0..97u32)),
                1 => u64::from(b.random::<f32>().to_bits()),
                _ => b.next_u64(),
            })
            .collect();
        assert_eq!(skip.len(), 400);
        assert_eq!(a.state(), b.state());
        for _ in 0..100 {
            assert_eq!(a.next_u64(), b.next_u64());
        }
    }
}
