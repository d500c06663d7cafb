//! Aggregate scores as deep RL reports them today: the interquartile mean
//! with a stratified bootstrap confidence interval, and the probability of
//! improvement (Agarwal et al. 2021, "Deep Reinforcement Learning at the
//! Edge of the Statistical Precipice", the protocol of the `rliable`
//! library).
//!
//! A *stratum* is one task (here: one maze and task); its samples are the
//! scores of the runs, one per training seed. The bootstrap resamples runs
//! with replacement inside every stratum, so that each resample keeps the
//! number of runs per task, and takes the percentile interval of the
//! statistic over the resamples. Every resampling is seeded: the same scores
//! give the same interval.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// Bootstrap resamples per interval (`rliable` uses 50,000 for its figures
/// and 2,000 in its examples; the intervals here move in the third digit
/// between the two).
pub const BOOTSTRAP_REPS: usize = 2_000;

/// The seed of every bootstrap, so a table is reproducible.
pub const BOOTSTRAP_SEED: u64 = 0x5249_4c49_4142; // "RILIAB"

/// A point estimate and its confidence interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The statistic on the scores themselves.
    pub point: f64,
    /// Lower end of the interval.
    pub lo: f64,
    /// Upper end of the interval.
    pub hi: f64,
}

/// The mean of the middle half: the scores sorted, `⌊n/4⌋` dropped from each
/// end (`scipy.stats.trim_mean(x, 0.25)`, which `rliable` calls). For fewer
/// than four scores nothing is dropped: the mean. `NaN` for no scores.
pub fn iqm(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    let mid = &v[cut..v.len() - cut];
    mid.iter().sum::<f64>() / mid.len() as f64
}

/// The IQM of all runs of all strata pooled (`rliable`'s aggregate over a
/// runs × tasks score matrix).
pub fn pooled_iqm(strata: &[Vec<f64>]) -> f64 {
    let all: Vec<f64> = strata.iter().flatten().copied().collect();
    iqm(&all)
}

/// `P(X > Y)`: the probability that a run of X scores above a run of Y on
/// the same task, ties counted half (the Mann–Whitney U statistic over
/// `|x|·|y|`), averaged over the strata that both have runs in.
/// `NaN` when no stratum has runs of both.
pub fn probability_of_improvement(x: &[Vec<f64>], y: &[Vec<f64>]) -> f64 {
    let mut total = 0.0;
    let mut tasks = 0usize;
    for (xs, ys) in x.iter().zip(y) {
        if xs.is_empty() || ys.is_empty() {
            continue;
        }
        let mut wins = 0.0;
        for a in xs {
            for b in ys {
                wins += if a > b {
                    1.0
                } else if a == b {
                    0.5
                } else {
                    0.0
                };
            }
        }
        total += wins / (xs.len() * ys.len()) as f64;
        tasks += 1;
    }
    if tasks == 0 {
        f64::NAN
    } else {
        total / tasks as f64
    }
}

/// One stratified resample: every stratum's runs drawn with replacement,
/// as many as it has.
fn resample(strata: &[Vec<f64>], rng: &mut SmallRng) -> Vec<Vec<f64>> {
    strata
        .iter()
        .map(|s| {
            (0..s.len())
                .map(|_| s[rng.random_range(0..s.len())])
                .collect()
        })
        .collect()
}

/// The `level` percentile interval (0.95: the 2.5th and 97.5th
/// percentiles) of `values`, linearly interpolated as `numpy.percentile`.
fn percentile_interval(mut values: Vec<f64>, level: f64) -> (f64, f64) {
    values.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let pos = q * (values.len() - 1) as f64;
        let (i, frac) = (pos.floor() as usize, pos - pos.floor());
        let j = (i + 1).min(values.len() - 1);
        values[i] + (values[j] - values[i]) * frac
    };
    let tail = (1.0 - level) / 2.0;
    (at(tail), at(1.0 - tail))
}

/// The pooled IQM of `strata` with its stratified bootstrap `level`
/// interval over `reps` resamples. `None` when there are no scores.
pub fn iqm_interval(strata: &[Vec<f64>], level: f64, reps: usize, seed: u64) -> Option<Estimate> {
    if strata.iter().all(Vec::is_empty) || reps == 0 {
        return None;
    }
    let mut rng = SmallRng::seed_from_u64(seed);
    let stats: Vec<f64> = (0..reps)
        .map(|_| pooled_iqm(&resample(strata, &mut rng)))
        .collect();
    let (lo, hi) = percentile_interval(stats, level);
    Some(Estimate {
        point: pooled_iqm(strata),
        lo,
        hi,
    })
}

/// [`probability_of_improvement`] of X over Y with its stratified bootstrap
/// interval (X's and Y's runs resampled independently inside each stratum).
/// `None` when no stratum has runs of both.
pub fn improvement_interval(
    x: &[Vec<f64>],
    y: &[Vec<f64>],
    level: f64,
    reps: usize,
    seed: u64,
) -> Option<Estimate> {
    let point = probability_of_improvement(x, y);
    if point.is_nan() || reps == 0 {
        return None;
    }
    let mut rng = SmallRng::seed_from_u64(seed);
    let stats: Vec<f64> = (0..reps)
        .map(|_| {
            let (rx, ry) = (resample(x, &mut rng), resample(y, &mut rng));
            probability_of_improvement(&rx, &ry)
        })
        .collect();
    let (lo, hi) = percentile_interval(stats, level);
    Some(Estimate { point, lo, hi })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_iqm_drops_a_quarter_from_each_end_as_scipy_trim_mean() {
        // scipy.stats.trim_mean(range(1, 9), 0.25) == 4.5
        assert_eq!(iqm(&[8.0, 1.0, 2.0, 7.0, 3.0, 6.0, 4.0, 5.0]), 4.5);
        // One outlier among eight does not move it.
        assert_eq!(iqm(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 1000.0]), 4.5);
        // trim_mean([1, 2, 3, 100, 5], 0.25) drops one from each end.
        assert!((iqm(&[1.0, 2.0, 3.0, 100.0, 5.0]) - 10.0 / 3.0).abs() < 1e-12);
        // Three seeds: nothing to drop, the mean.
        assert_eq!(iqm(&[1.0, 2.0, 6.0]), 3.0);
        assert!(iqm(&[]).is_nan());
    }

    #[test]
    fn probability_of_improvement_counts_pairs_and_ties_half() {
        let x = vec![vec![3.0, 4.0], vec![1.0]];
        let y = vec![vec![1.0, 4.0], vec![1.0]];
        // Task 1: (3>1)=1, (3<4)=0, (4>1)=1, (4=4)=½ → 2.5/4; task 2: ½.
        assert!((probability_of_improvement(&x, &y) - (0.625 + 0.5) / 2.0).abs() < 1e-12);
        // X over Y and Y over X add to one.
        let back = probability_of_improvement(&y, &x);
        assert!((probability_of_improvement(&x, &y) + back - 1.0).abs() < 1e-12);
        // A task where one side has no runs is left out.
        let y_missing = vec![vec![1.0, 4.0], vec![]];
        assert!((probability_of_improvement(&x, &y_missing) - 0.625).abs() < 1e-12);
        assert!(probability_of_improvement(&[vec![]], &[vec![1.0]]).is_nan());
    }

    #[test]
    fn the_bootstrap_interval_holds_the_point_is_seeded_and_narrows_with_runs() {
        let few = vec![vec![2.9, 3.1, 3.4]];
        let a = iqm_interval(&few, 0.95, BOOTSTRAP_REPS, 7).unwrap();
        assert_eq!(a, iqm_interval(&few, 0.95, BOOTSTRAP_REPS, 7).unwrap());
        assert!(a.lo <= a.point && a.point <= a.hi, "{a:?}");
        assert!(a.lo >= 2.9 && a.hi <= 3.4, "{a:?}");
        // Twelve runs of the same spread: a narrower interval.
        let many = vec![few[0].iter().cycle().take(12).copied().collect::<Vec<_>>()];
        let b = iqm_interval(&many, 0.95, BOOTSTRAP_REPS, 7).unwrap();
        assert!(b.hi - b.lo < a.hi - a.lo, "{a:?} {b:?}");
        // Strata are resampled within themselves: two tasks far apart keep
        // every resample's pool half from each, so the interval stays
        // between them instead of spanning both.
        let two = vec![vec![0.0, 0.1, 0.2], vec![10.0, 10.1, 10.2]];
        let c = iqm_interval(&two, 0.95, BOOTSTRAP_REPS, 7).unwrap();
        assert!(c.lo > 4.0 && c.hi < 6.2, "{c:?}");
    }

    #[test]
    fn the_bootstrap_interval_of_small_samples_equals_the_hand_computed_one() {
        // Two runs [1, 3]: a resample is (1,1), (1,3), (3,1) or (3,3), so its
        // IQM (the mean: fewer than four runs) is 1 with probability ¼, 2
        // with ½ and 3 with ¼; the 2.5th and 97.5th percentiles of 2000
        // resamples fall inside the ¼ masses at the ends: exactly [1, 3].
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        let e = iqm_interval(&[vec![1.0, 3.0]], 0.95, BOOTSTRAP_REPS, 3).unwrap();
        assert!(
            close(e.point, 2.0) && close(e.lo, 1.0) && close(e.hi, 3.0),
            "{e:?}"
        );
        // Three runs: each end is a resample of one run repeated, mass 1/27
        // (about 74 of 2000 resamples, above the 50 of each 2.5 % tail).
        let e = iqm_interval(&[vec![2.9, 3.1, 3.4]], 0.95, BOOTSTRAP_REPS, 3).unwrap();
        assert!(
            close(e.point, 9.4 / 3.0) && close(e.lo, 2.9) && close(e.hi, 3.4),
            "{e:?}"
        );
        // Two strata, [0, 1] and [10]: the pool is resampled within each, so
        // its mean is (0+0+10)/3, (0+1+10)/3 or (1+1+10)/3 with ¼, ½, ¼.
        let e = iqm_interval(&[vec![0.0, 1.0], vec![10.0]], 0.95, BOOTSTRAP_REPS, 3).unwrap();
        assert!(
            close(e.point, 11.0 / 3.0) && close(e.lo, 10.0 / 3.0) && close(e.hi, 4.0),
            "{e:?}"
        );
        // One run: no spread to resample.
        let e = iqm_interval(&[vec![4.2]], 0.95, BOOTSTRAP_REPS, 3).unwrap();
        assert_eq!((e.point, e.lo, e.hi), (4.2, 4.2, 4.2));
    }

    #[test]
    fn an_agent_better_on_every_run_has_improvement_one_with_a_tight_interval() {
        let x = vec![vec![5.0, 5.2, 5.1]];
        let y = vec![vec![3.0, 3.1, 2.9]];
        let e = improvement_interval(&x, &y, 0.95, BOOTSTRAP_REPS, 1).unwrap();
        assert_eq!((e.point, e.lo, e.hi), (1.0, 1.0, 1.0));
        let overlap = vec![vec![3.0, 3.3, 2.8]];
        let f = improvement_interval(&overlap, &y, 0.95, BOOTSTRAP_REPS, 1).unwrap();
        assert!(f.lo < f.point && f.point < f.hi, "{f:?}");
        assert!(improvement_interval(&[vec![]], &y, 0.95, BOOTSTRAP_REPS, 1).is_none());
    }
}
