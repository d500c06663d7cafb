//! The state-conditioned prior `p_ψ(z_t | s_t) = Beta(α_t, β_t)` of the
//! pivotal-state latent model, and its KL term (Shang et al. 2019,
//! arXiv:1907.00664, section 3.1: "the prior mean for each `z_t` signifies
//! on average how necessary `s_t` is for action reconstruction").
//!
//! The ELBO's KL is taken between the unstretched Kumaraswamy posterior
//! `Kuma(ã, 1)` and the Beta prior: the rectified HardKuma has point masses,
//! so its KL to a continuous Beta is undefined (docs/latent-model-math.md).
//! For `b = 1` the series of Nalisnick & Smyth (2016) sums in closed form;
//! this module uses that exact form, not the truncated general-`b` series
//! (20–25% off for small `a` when `β ≠ 1`, per the notes).

use tch::Tensor;

use super::hardkuma::positive_parameter;

/// Euler–Mascheroni constant `γ`.
pub const EULER_GAMMA: f64 = 0.577_215_664_901_532_9;

/// `Beta(α, β)` for tensors of parameters of one shape (e.g. `[T, B]`), each
/// assumed in the safe range of [`positive_parameter`].
#[derive(Debug)]
pub struct BetaPrior {
    /// `α_t`.
    pub alpha: Tensor,
    /// `β_t`.
    pub beta: Tensor,
}

impl BetaPrior {
    /// Wraps parameters that are already positive.
    pub fn new(alpha: Tensor, beta: Tensor) -> Self {
        Self { alpha, beta }
    }

    /// Builds the prior from raw network outputs (`softplus` + clamp).
    pub fn from_raw(raw_alpha: &Tensor, raw_beta: &Tensor) -> Self {
        Self::new(positive_parameter(raw_alpha), positive_parameter(raw_beta))
    }

    /// The prior mean `α / (α + β)`: the pivotality of the state.
    pub fn mean(&self) -> Tensor {
        &self.alpha / (&self.alpha + &self.beta)
    }

    /// `log B(α, β) = lgamma(α) + lgamma(β) − lgamma(α + β)`.
    pub fn log_beta_function(&self) -> Tensor {
        self.alpha.lgamma() + self.beta.lgamma() - (&self.alpha + &self.beta).lgamma()
    }

    /// Exact `KL(Kuma(a, 1) ‖ Beta(α, β))`, element-wise:
    ///
    /// ```text
    /// KL = (α − a)/a + log a + log B(α, β) + (β − 1)·(ψ(a + 1) + γ)
    /// ```
    ///
    /// with `ψ` the digamma function and `γ` the Euler–Mascheroni constant
    /// (docs/latent-model-math.md, checked against quadrature there).
    /// `a` has the prior's shape.
    pub fn kl_from_kuma(&self, a: &Tensor) -> Tensor {
        (&self.alpha - a) / a
            + a.log()
            + self.log_beta_function()
            + (&self.beta - 1.0) * ((a + 1.0).digamma() + EULER_GAMMA)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vae::hardkuma::{PARAM_MAX, PARAM_MIN};
    use tch::Kind;

    fn kl(a: f64, alpha: f64, beta: f64) -> f64 {
        let prior = BetaPrior::new(Tensor::from(alpha), Tensor::from(beta));
        prior.kl_from_kuma(&Tensor::from(a)).double_value(&[])
    }

    fn ln_gamma(x: f64) -> f64 {
        Tensor::from(x).lgamma().double_value(&[])
    }

    /// `KL(Kuma(a,1) ‖ Beta(α,β)) = ∫ q log(q/p)` by the midpoint rule after
    /// the substitution `x = y^k`, which flattens the endpoint singularities
    /// of both densities (`q(x) = a·x^{a−1}`).
    fn kl_by_quadrature(a: f64, alpha: f64, beta: f64) -> f64 {
        let log_b = ln_gamma(alpha) + ln_gamma(beta) - ln_gamma(alpha + beta);
        let k = 6.0;
        let n = 400_000;
        let mut total = 0.0;
        for i in 0..n {
            let y = (i as f64 + 0.5) / n as f64;
            let x = y.powf(k);
            let dx = k * y.powf(k - 1.0) / n as f64;
            let log_q = a.ln() + (a - 1.0) * x.ln();
            let log_p = (alpha - 1.0) * x.ln() + (beta - 1.0) * (-x).ln_1p() - log_b;
            total += log_q.exp() * (log_q - log_p) * dx;
        }
        total
    }

    #[test]
    fn closed_form_matches_the_quadrature_table_of_the_notes() {
        // (a, α, β, quadrature) from docs/latent-model-math.md.
        let table = [
            (0.5, 1.0, 3.0, 0.43565),
            (2.0, 0.5, 0.5, 0.33788),
            (1.3, 2.0, 5.0, 2.10865),
            (3.0, 1.0, 1.0, 0.43195),
            (0.7, 4.0, 0.8, 3.26295),
        ];
        for (a, alpha, beta, expected) in table {
            let got = kl(a, alpha, beta);
            eprintln!("KL({a}; {alpha}, {beta}): closed {got:.6}, table {expected}");
            assert!(
                (got - expected).abs() < 1e-5,
                "KL({a}; {alpha}, {beta}) = {got}, table {expected}"
            );
        }
    }

    #[test]
    fn closed_form_matches_own_quadrature_on_fresh_cases() {
        for (a, alpha, beta) in [(0.35, 1.7, 2.4), (4.0, 6.0, 0.6), (1.0, 0.8, 1.9)] {
            let (closed, numeric) = (kl(a, alpha, beta), kl_by_quadrature(a, alpha, beta));
            eprintln!("KL({a}; {alpha}, {beta}): closed {closed:.7}, quadrature {numeric:.7}");
            assert!(
                (closed - numeric).abs() < 1e-4,
                "KL({a}; {alpha}, {beta}): closed {closed}, quadrature {numeric}"
            );
        }
    }

    #[test]
    fn kl_vanishes_when_the_distributions_coincide() {
        // Kuma(a, 1) = Beta(a, 1).
        for a in [0.3, 1.0, 2.5] {
            assert!(kl(a, a, 1.0).abs() < 1e-12, "a = {a}");
        }
    }

    #[test]
    fn gradients_reach_posterior_and_prior_parameters() {
        let raw_a = Tensor::from_slice(&[-1.0_f64, 0.2, 2.0]).set_requires_grad(true);
        let raw_alpha = Tensor::from_slice(&[0.5_f64, -0.3, 1.5]).set_requires_grad(true);
        let raw_beta = Tensor::from_slice(&[1.0_f64, 0.0, -2.0]).set_requires_grad(true);
        let a = positive_parameter(&raw_a);
        let prior = BetaPrior::from_raw(&raw_alpha, &raw_beta);
        prior.kl_from_kuma(&a).sum(None).backward();
        for (name, raw) in [("ã", &raw_a), ("α", &raw_alpha), ("β", &raw_beta)] {
            let grad = raw.grad();
            let finite = grad
                .isfinite()
                .all()
                .to_kind(Kind::Double)
                .double_value(&[]);
            assert_eq!(finite, 1.0, "{name}: {grad}");
            let smallest = grad.abs().min().double_value(&[]);
            assert!(
                smallest > 0.0,
                "{name}: every element needs a gradient, {grad}"
            );
        }
    }

    #[test]
    fn no_nan_at_the_clamp_limits() {
        let limits = [PARAM_MIN, 1.0, PARAM_MAX];
        for a in limits {
            for alpha in limits {
                for beta in limits {
                    let value = kl(a, alpha, beta);
                    assert!(value.is_finite(), "KL({a}; {alpha}, {beta}) = {value}");
                    assert!(value > -1e-9, "KL is non-negative: {value}");
                }
            }
        }
        let raw = Tensor::from_slice(&[-1e4_f64, 1e4]).set_requires_grad(true);
        let prior = BetaPrior::from_raw(&raw, &raw);
        let a = positive_parameter(&raw);
        prior.kl_from_kuma(&a).sum(None).backward();
        let finite = raw
            .grad()
            .isfinite()
            .all()
            .to_kind(Kind::Double)
            .double_value(&[]);
        assert_eq!(finite, 1.0);
    }

    #[test]
    fn prior_mean_is_alpha_over_alpha_plus_beta() {
        let prior = BetaPrior::new(
            Tensor::from_slice(&[1.0_f64, 3.0]),
            Tensor::from_slice(&[3.0_f64, 1.0]),
        );
        let mean = prior.mean();
        assert!((mean.double_value(&[0]) - 0.25).abs() < 1e-15);
        assert!((mean.double_value(&[1]) - 0.75).abs() < 1e-15);
    }
}
