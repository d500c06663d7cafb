//! The latent model's training buffer (step 2 of a round): each source's
//! share of a round held out to measure the reconstruction accuracy, the
//! newest trajectories of each source kept, and batches drawn from the
//! sources by their shares ([`super::DiscoveryConfig::buffer`]).

use rand::Rng;
use rand::rngs::SmallRng;

use crate::vae::Trajectory;

/// Trajectories of each source held out of a round's training to measure
/// the reconstruction accuracy.
pub(super) const EVAL_PER_SOURCE: usize = 128;

/// Splits `all` into (every `k`-th, up to `n`; the rest), keeping order:
/// the held-out share is spread over the round.
pub(super) fn hold_out(all: Vec<Trajectory>, n: usize) -> (Vec<Trajectory>, Vec<Trajectory>) {
    // Hold out at most a quarter, so a short round still trains.
    let n = n.min(all.len() / 4);
    let k = all.len().checked_div(n).unwrap_or(usize::MAX);
    let (mut held, mut rest) = (Vec::new(), Vec::new());
    for (i, t) in all.into_iter().enumerate() {
        if held.len() < n && i % k == 0 {
            held.push(t);
        } else {
            rest.push(t);
        }
    }
    (held, rest)
}

/// Appends `fresh` to `buffer`, then drops the oldest beyond `cap`.
pub(super) fn push_newest(buffer: &mut Vec<Trajectory>, fresh: Vec<Trajectory>, cap: usize) {
    buffer.extend(fresh);
    if buffer.len() > cap {
        let excess = buffer.len() - cap;
        buffer.drain(..excess);
    }
}

/// `size` trajectories, each source's share (renormalised over the sources
/// that hold any) drawn uniformly from it. The sources take turns by
/// largest shortfall, ties to the first, so two equal shares alternate.
/// At least one source must hold a trajectory.
pub(super) fn mixed_batch(
    sources: &[(&[Trajectory], f64)],
    size: usize,
    rng: &mut SmallRng,
) -> Vec<Trajectory> {
    let total: f64 = sources
        .iter()
        .filter(|(s, _)| !s.is_empty())
        .map(|&(_, w)| w)
        .sum();
    let share = |(s, w): &(&[Trajectory], f64)| if s.is_empty() { 0.0 } else { w / total };
    let mut drawn = vec![0usize; sources.len()];
    (0..size)
        .map(|k| {
            let mut pick = None;
            let mut most = f64::NEG_INFINITY;
            for (i, src) in sources.iter().enumerate() {
                let shortfall = share(src) * (k + 1) as f64 - drawn[i] as f64;
                if share(src) > 0.0 && shortfall > most {
                    (pick, most) = (Some(i), shortfall);
                }
            }
            let i = pick.expect("invariant: some source holds a trajectory");
            drawn[i] += 1;
            let from = sources[i].0;
            from[rng.random_range(0..from.len())].clone()
        })
        .collect()
}

/// The held-out trajectories in the training mix: as many of each source
/// that has any (the smallest count).
pub(super) fn mixed_eval(sources: &[&[Trajectory]]) -> Vec<Trajectory> {
    let n = sources
        .iter()
        .map(|s| s.len())
        .filter(|&n| n > 0)
        .min()
        .unwrap_or(0);
    sources
        .iter()
        .flat_map(|s| s.iter().take(n))
        .cloned()
        .collect()
}
