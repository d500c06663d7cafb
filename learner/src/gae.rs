//! Generalized advantage estimation (Schulman et al. 2016, "High-Dimensional
//! Continuous Control Using Generalized Advantage Estimation", eq. 16), the
//! advantage estimator of the A2C learners of Shang et al. 2019
//! (arXiv:1907.00664): the goal-conditioned policy `π_g` (section 3.2) and
//! the stage-2 agents (section 4).
//!
//! Written as the backward recursion CleanRL uses, vectorised over the
//! batch and looped over time.

use tch::{Kind, Tensor};

/// Advantages and value targets of one rollout, both `[T, B]` float32.
#[derive(Debug)]
pub struct GaeOutput {
    /// `Â_t`, the λ-weighted sum of TD errors.
    pub advantages: Tensor,
    /// Value targets `R_t = Â_t + V(s_t)` (the λ-return).
    pub returns: Tensor,
}

/// Generalized advantage estimation over a rollout of `T` steps of `B`
/// environments:
///
/// ```text
/// next_nonterminal_t = 1 − done_t
/// delta_t            = r_t + γ · V(s_{t+1}) · next_nonterminal_t − V(s_t)
/// Â_t                = delta_t + γ · λ · next_nonterminal_t · Â_{t+1}
/// R_t                = Â_t + V(s_t)
/// ```
///
/// with `V(s_T) = bootstrap_value` and `Â_T = 0`.
///
/// - `rewards`, `values`, `dones`: `[T, B]`; `values[t]` is `V(s_t)`;
///   `dones[t] = 1` when the transition `s_t → s_{t+1}` ended the episode, so
///   `s_{t+1}` (the next episode's first state) is not bootstrapped from.
/// - `bootstrap_value`: `[B]`, `V(s_T)` of the state after the rollout.
///
/// The inputs are read without gradient (`values` is detached): the
/// advantages are constants of the policy-gradient loss and the returns are
/// the regression targets of the value loss.
pub fn generalized_advantages(
    rewards: &Tensor,
    values: &Tensor,
    dones: &Tensor,
    bootstrap_value: &Tensor,
    gamma: f64,
    gae_lambda: f64,
) -> GaeOutput {
    tch::no_grad(|| {
        let rewards = rewards.to_kind(Kind::Float);
        let values = values.detach().to_kind(Kind::Float);
        let dones = dones.to_kind(Kind::Float);
        let steps = rewards.size()[0];
        let advantages = rewards.zeros_like();
        let mut last_gae_lam = bootstrap_value.zeros_like().to_kind(Kind::Float);
        for t in (0..steps).rev() {
            let next_values = if t + 1 == steps {
                bootstrap_value.detach().to_kind(Kind::Float)
            } else {
                values.get(t + 1)
            };
            let next_nonterminal = dones.get(t).neg() + 1.0;
            let delta = rewards.get(t) + next_values * gamma * &next_nonterminal - values.get(t);
            last_gae_lam = delta + last_gae_lam * next_nonterminal * (gamma * gae_lambda);
            advantages.get(t).copy_(&last_gae_lam);
        }
        let returns = &advantages + &values;
        GaeOutput {
            advantages,
            returns,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};

    /// The textbook definition: `Â_t = Σ_{l≥0} (γλ)^l δ_{t+l}`, summed
    /// forward per environment and cut at the first episode end.
    #[allow(clippy::needless_range_loop)] // indices as in the formula
    fn naive(
        rewards: &[Vec<f64>],
        values: &[Vec<f64>],
        dones: &[Vec<f64>],
        bootstrap: &[f64],
        gamma: f64,
        lambda: f64,
    ) -> Vec<Vec<f64>> {
        let (t_len, b_len) = (rewards.len(), bootstrap.len());
        let value_at = |t: usize, b: usize| {
            if t == t_len {
                bootstrap[b]
            } else {
                values[t][b]
            }
        };
        let mut out = vec![vec![0.0; b_len]; t_len];
        for b in 0..b_len {
            for t in 0..t_len {
                let mut sum = 0.0;
                let mut weight = 1.0;
                for l in t..t_len {
                    let alive = 1.0 - dones[l][b];
                    let delta = rewards[l][b] + gamma * value_at(l + 1, b) * alive - values[l][b];
                    sum += weight * delta;
                    if alive == 0.0 {
                        break;
                    }
                    weight *= gamma * lambda;
                }
                out[t][b] = sum;
            }
        }
        out
    }

    fn to_tensor(rows: &[Vec<f64>]) -> Tensor {
        let flat: Vec<f32> = rows.iter().flatten().map(|&x| x as f32).collect();
        Tensor::from_slice(&flat).view([rows.len() as i64, -1])
    }

    #[test]
    fn recursion_matches_the_naive_sum_of_discounted_td_errors() {
        let mut rng = SmallRng::seed_from_u64(3);
        let (t_len, b_len) = (11, 7);
        let mut grid = |f: &mut dyn FnMut(&mut SmallRng) -> f64| -> Vec<Vec<f64>> {
            (0..t_len)
                .map(|_| (0..b_len).map(|_| f(&mut rng)).collect())
                .collect()
        };
        let rewards = grid(&mut |r| r.random_range(-1.0..1.0));
        let values = grid(&mut |r| r.random_range(-2.0..2.0));
        let dones = grid(&mut |r| if r.random_bool(0.2) { 1.0 } else { 0.0 });
        let bootstrap: Vec<f64> = (0..b_len).map(|b| 0.5 - b as f64 * 0.1).collect();
        for (gamma, lambda) in [(0.99, 0.95), (0.9, 1.0), (0.5, 0.0)] {
            let expected = naive(&rewards, &values, &dones, &bootstrap, gamma, lambda);
            let boot: Vec<f32> = bootstrap.iter().map(|&x| x as f32).collect();
            let out = generalized_advantages(
                &to_tensor(&rewards),
                &to_tensor(&values),
                &to_tensor(&dones),
                &Tensor::from_slice(&boot),
                gamma,
                lambda,
            );
            assert_eq!(out.advantages.size(), [t_len as i64, b_len as i64]);
            for t in 0..t_len {
                for b in 0..b_len {
                    let got = out.advantages.double_value(&[t as i64, b as i64]);
                    let ret = out.returns.double_value(&[t as i64, b as i64]);
                    assert!(
                        (got - expected[t][b]).abs() < 1e-4,
                        "γ={gamma} λ={lambda} t={t} b={b}: {got} vs {}",
                        expected[t][b]
                    );
                    assert!((ret - expected[t][b] - values[t][b]).abs() < 1e-4);
                }
            }
        }
    }

    #[test]
    fn lambda_zero_is_the_one_step_td_error() {
        let rewards = Tensor::from_slice(&[1.0_f32, 0.0, 2.0]).view([3, 1]);
        let values = Tensor::from_slice(&[0.5_f32, 0.25, 1.0]).view([3, 1]);
        let dones = Tensor::from_slice(&[0.0_f32, 1.0, 0.0]).view([3, 1]);
        let out = generalized_advantages(
            &rewards,
            &values,
            &dones,
            &Tensor::from_slice(&[4.0_f32]),
            0.5,
            0.0,
        );
        let adv: Vec<f32> = Vec::try_from(out.advantages.flatten(0, -1)).expect("float tensor");
        // 1 + 0.5·0.25 − 0.5; 0 − 0.25 (episode ended); 2 + 0.5·4 − 1.
        assert_eq!(adv, vec![0.625, -0.25, 3.0]);
    }
}
