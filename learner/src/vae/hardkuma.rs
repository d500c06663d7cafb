//! The HardKuma posterior `q_φ(z_t | a, s) = HardKuma(ã_t, 1)` of the
//! pivotal-state latent model (Shang et al. 2019, arXiv:1907.00664,
//! section 3.1; Bastings et al. 2019 for the distribution).
//!
//! A Kumaraswamy variable `x ∈ (0, 1)` with CDF `F(x) = 1 − (1 − x^a)^b` is
//! stretched to `(l, r)` with `l < 0 < 1 < r` and rectified into `[0, 1]`, so
//! that `z = 0` and `z = 1` carry probability mass while samples stay
//! differentiable in `a`. The paper fixes `b = 1` ("we fix β̃_t = 1 to ease
//! optimization"), and so does this module: every formula below is the
//! `b = 1` case of docs/latent-model-math.md (shared notes), where each one
//! was checked numerically.
//!
//! All functions are element-wise on tensors of any shape and any floating
//! kind (float64 in the unit tests, float32 in training).

use rand::rngs::SmallRng;
use tch::Tensor;

use crate::seeding::uniform_like;

/// Lower end `l` of the stretched support (Bastings et al. 2019).
pub const STRETCH_LOW: f64 = -0.1;
/// Upper end `r` of the stretched support.
pub const STRETCH_HIGH: f64 = 1.1;
/// `u ~ U(ε, 1 − ε)` keeps `ln u` and the gradient of `u^{1/a}` finite.
pub const UNIFORM_EPS: f64 = 1e-3;
/// Safe range of every distribution parameter (`ã`, `α`, `β`): outside it
/// `lgamma`, `digamma` and `x^{1/a}` overflow (notes, "Parameterisation").
pub const PARAM_MIN: f64 = 1e-3;
/// Upper end of the safe parameter range.
pub const PARAM_MAX: f64 = 100.0;

/// `t0 = −l / (r − l)`: the Kumaraswamy value stretched onto 0 (1/12).
pub const fn t0() -> f64 {
    -STRETCH_LOW / (STRETCH_HIGH - STRETCH_LOW)
}

/// `t1 = (1 − l) / (r − l)`: the Kumaraswamy value stretched onto 1 (11/12).
pub const fn t1() -> f64 {
    (1.0 - STRETCH_LOW) / (STRETCH_HIGH - STRETCH_LOW)
}

/// Maps an unconstrained network output to a distribution parameter:
/// `clamp(softplus(raw), PARAM_MIN, PARAM_MAX)`, element-wise.
pub fn positive_parameter(raw: &Tensor) -> Tensor {
    raw.softplus().clamp(PARAM_MIN, PARAM_MAX)
}

/// `HardKuma(a, 1)` for a tensor of shape parameters `a` (any shape, e.g.
/// `[T, B]`), each assumed in `[PARAM_MIN, PARAM_MAX]`.
#[derive(Debug)]
pub struct HardKuma {
    /// The shape parameter `ã` (the paper's `α̃_t`).
    pub a: Tensor,
}

impl HardKuma {
    /// Wraps shape parameters that are already positive.
    pub fn new(a: Tensor) -> Self {
        Self { a }
    }

    /// Builds the distribution from raw network outputs through
    /// [`positive_parameter`].
    pub fn from_raw(raw: &Tensor) -> Self {
        Self::new(positive_parameter(raw))
    }

    /// Reparameterised sample with fresh noise `u ~ U(ε, 1 − ε)` drawn from
    /// `rng` (see [`crate::seeding`]); see [`HardKuma::sample_with_noise`].
    pub fn rsample(&self, rng: &mut SmallRng) -> Tensor {
        let u = uniform_like(rng, &self.a, UNIFORM_EPS, 1.0 - UNIFORM_EPS);
        self.sample_with_noise(&u)
    }

    /// Stretch and rectify, for given uniform noise `u` (same shape as `a`):
    ///
    /// ```text
    /// x = (1 − (1 − u)^{1/b})^{1/a} = u^{1/a}        (b = 1)
    /// s = l + (r − l)·x
    /// z = min(1, max(0, s))
    /// ```
    ///
    /// `z` has exact 0s and 1s, and a gradient with respect to `a` wherever
    /// `0 < s < 1`. `u^{1/a}` is computed as `exp(ln(u)/a)`.
    pub fn sample_with_noise(&self, u: &Tensor) -> Tensor {
        let x = (u.log() / &self.a).exp();
        let s = x * (STRETCH_HIGH - STRETCH_LOW) + STRETCH_LOW;
        s.clamp(0.0, 1.0)
    }

    /// `P(z = 0) = F(t0) = 1 − (1 − t0^a)^b = t0^a` for `b = 1`.
    pub fn prob_zero(&self) -> Tensor {
        (&self.a * t0().ln()).exp()
    }

    /// `P(z = 1) = 1 − F(t1) = (1 − t1^a)^b = 1 − t1^a` for `b = 1`.
    pub fn prob_one(&self) -> Tensor {
        1.0 - (&self.a * t1().ln()).exp()
    }

    /// The evaluation-time value of `z`: the most likely of the three parts
    /// `{0}`, `(0, 1)`, `{1}` (notes, "At evaluation time"); inside `(0, 1)`
    /// it is the stretched Kumaraswamy median `l + (r − l)·0.5^{1/a}`
    /// (clamped, so it may itself be 0 or 1 when the continuous part is
    /// the likeliest but its median falls outside).
    pub fn decide(&self) -> Tensor {
        let p0 = self.prob_zero();
        let p1 = self.prob_one();
        let p_between = 1.0 - &p0 - &p1;
        let median = self.sample_with_noise(&self.a.full_like(0.5));
        let zero_wins = p0.ge_tensor(&p1).logical_and(&p0.ge_tensor(&p_between));
        let one_wins = p1.gt_tensor(&p0).logical_and(&p1.ge_tensor(&p_between));
        median
            .where_self(&zero_wins.logical_not(), &median.zeros_like())
            .where_self(&one_wins.logical_not(), &median.ones_like())
    }
}

/// Expected number of non-zero latents along each trajectory:
///
/// ```text
/// E[Σ_t 1{z_t ≠ 0}] = Σ_t (1 − P0_t) · m_t
/// ```
///
/// `prob_zero`: `[T, B]` values `P0_t = P(z_t = 0)`; `mask`: `[T, B]`, 1 on the
/// states that count (0 on padding). Returns `[B]`.
pub fn expected_nonzero(prob_zero: &Tensor, mask: &Tensor) -> Tensor {
    ((1.0_f64 - prob_zero) * mask).sum_dim_intlist(0_i64, false, None::<tch::Kind>)
}

/// Expected number of changes between "zero" and "non-zero" along each
/// trajectory (the fused-lasso surrogate of the notes; the `z_t` are
/// independent given the encoder output):
///
/// ```text
/// E[Σ_t 1{z_t ≠ z_{t+1}}] ≈ Σ_t [P0_t·(1 − P0_{t+1}) + (1 − P0_t)·P0_{t+1}] · m_t·m_{t+1}
/// ```
///
/// `prob_zero`, `mask`: `[T, B]`. Returns `[B]`.
pub fn expected_transitions(prob_zero: &Tensor, mask: &Tensor) -> Tensor {
    let len = prob_zero.size()[0];
    if len < 2 {
        return prob_zero
            .zeros_like()
            .sum_dim_intlist(0_i64, false, None::<tch::Kind>);
    }
    let now = prob_zero.narrow(0, 0, len - 1);
    let next = prob_zero.narrow(0, 1, len - 1);
    let pair_mask = mask.narrow(0, 0, len - 1) * mask.narrow(0, 1, len - 1);
    let change: Tensor = &now * (1.0_f64 - &next) + (1.0_f64 - &now) * &next;
    (change * pair_mask).sum_dim_intlist(0_i64, false, None::<tch::Kind>)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::{Device, Kind};

    const F64: (Kind, Device) = (Kind::Double, Device::Cpu);

    fn scalar(t: &Tensor) -> f64 {
        t.double_value(&[])
    }

    #[test]
    fn stretch_points_are_one_twelfth_and_eleven_twelfths() {
        assert!((t0() - 1.0 / 12.0).abs() < 1e-15);
        assert!((t1() - 11.0 / 12.0).abs() < 1e-15);
    }

    #[test]
    fn point_masses_match_the_checked_values_and_monte_carlo() {
        let mut rng = rand::SeedableRng::seed_from_u64(11);
        let kuma = HardKuma::new(Tensor::from_slice(&[0.5_f64]));
        // The notes' check: a = 0.5 gives P0 = 0.2887, P1 = 0.0426.
        let (p0, p1) = (
            scalar(&kuma.prob_zero().get(0)),
            scalar(&kuma.prob_one().get(0)),
        );
        assert!((p0 - 0.2887).abs() < 5e-5, "P0 = {p0}");
        assert!((p1 - 0.0426).abs() < 5e-5, "P1 = {p1}");

        // Monte Carlo over 1M samples, for several a: standard error ≤ 5e-4.
        let n = 1_000_000;
        for a in [0.2_f64, 0.5, 1.0, 3.0] {
            let kuma = HardKuma::new(Tensor::full([n], a, F64));
            let z = kuma.rsample(&mut rng);
            let mc0 = scalar(&z.eq(0.0).to_kind(Kind::Double).mean(None));
            let mc1 = scalar(&z.eq(1.0).to_kind(Kind::Double).mean(None));
            let p0 = t0().powf(a);
            let p1 = 1.0 - t1().powf(a);
            // ε-truncation of u moves the masses by at most ε = 1e-3.
            assert!((mc0 - p0).abs() < 3e-3, "a={a}: MC P0 {mc0} vs {p0}");
            assert!((mc1 - p1).abs() < 3e-3, "a={a}: MC P1 {mc1} vs {p1}");
        }
    }

    #[test]
    fn samples_lie_in_the_unit_interval_with_exact_zeros_and_ones() {
        let mut rng = rand::SeedableRng::seed_from_u64(3);
        let kuma = HardKuma::new(Tensor::full([20_000], 0.8, F64));
        let z = kuma.rsample(&mut rng);
        assert!(scalar(&z.min()) == 0.0, "exact zeros expected");
        assert!(scalar(&z.max()) == 1.0, "exact ones expected");
        let between = z.gt(0.0).logical_and(&z.lt(1.0));
        let frac_between = scalar(&between.to_kind(Kind::Double).mean(None));
        assert!(
            frac_between > 0.3,
            "continuous part present: {frac_between}"
        );
    }

    #[test]
    fn gradient_reaches_the_shape_parameter_through_samples_and_masses() {
        let mut rng = rand::SeedableRng::seed_from_u64(5);
        let raw = Tensor::full([1000], 0.3, F64).set_requires_grad(true);
        let kuma = HardKuma::from_raw(&raw);
        let loss = kuma.rsample(&mut rng).sum(None) + kuma.prob_zero().sum(None);
        loss.backward();
        let grad = raw.grad();
        assert!(scalar(&grad.isfinite().all().to_kind(Kind::Double)) == 1.0);
        assert!(scalar(&grad.abs().sum(None)) > 0.0);
    }

    #[test]
    fn clamp_limits_give_finite_values_and_gradients() {
        let mut rng = rand::SeedableRng::seed_from_u64(9);
        let raw = Tensor::from_slice(&[-1e4_f64, -50.0, 0.0, 50.0, 1e4]).set_requires_grad(true);
        let kuma = HardKuma::from_raw(&raw);
        let a = &kuma.a;
        assert!(scalar(&a.min()) >= PARAM_MIN && scalar(&a.max()) <= PARAM_MAX);
        let z = kuma.rsample(&mut rng);
        let total = z.sum(None) + kuma.prob_zero().sum(None) + kuma.prob_one().sum(None);
        total.backward();
        for t in [&z, &kuma.prob_zero(), &kuma.prob_one(), &raw.grad()] {
            assert!(
                scalar(&t.isfinite().all().to_kind(Kind::Double)) == 1.0,
                "{t}"
            );
        }
        // Tiny a: x = u^{1/a} underflows to 0, so z = 0 almost surely.
        assert!(scalar(&z.get(0)) == 0.0);
    }

    #[test]
    fn decision_picks_the_likeliest_part() {
        // a = 0.01: P0 = 0.975 → 0; a = 60: P1 = 1 − (11/12)^60 = 0.9946 → 1;
        // a = 1: P0 = 1/12, P1 = 1/12, continuous part 5/6 → median 0.5.
        let kuma = HardKuma::new(Tensor::from_slice(&[0.01_f64, 60.0, 1.0]));
        let z = kuma.decide();
        assert_eq!(scalar(&z.get(0)), 0.0);
        assert_eq!(scalar(&z.get(1)), 1.0);
        assert!((scalar(&z.get(2)) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn expectations_match_monte_carlo_and_respect_the_mask() {
        let mut rng = rand::SeedableRng::seed_from_u64(21);
        // [T = 4, B = 2]; the second trajectory has 3 states (last is padding).
        let a = Tensor::from_slice(&[0.3_f64, 2.0, 1.0, 0.5, 4.0, 0.1, 0.7, 9.0]).view([4, 2]);
        let mask = Tensor::from_slice(&[1.0_f64, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0]).view([4, 2]);
        let kuma = HardKuma::new(a.shallow_clone());
        let p0 = kuma.prob_zero();
        let kept = expected_nonzero(&p0, &mask);
        let changes = expected_transitions(&p0, &mask);

        let n = 200_000;
        let z =
            HardKuma::new(a.unsqueeze(0).expand([n, 4, 2], false).contiguous()).rsample(&mut rng);
        let nonzero = z.ne(0.0).to_kind(Kind::Double) * mask.unsqueeze(0);
        let mc_kept = nonzero
            .sum_dim_intlist(1_i64, false, None::<Kind>)
            .mean_dim(0_i64, false, None::<Kind>);
        let flips = (nonzero.narrow(1, 0, 3) - nonzero.narrow(1, 1, 3)).abs()
            * (mask.narrow(0, 0, 3) * mask.narrow(0, 1, 3)).unsqueeze(0);
        let mc_changes =
            flips
                .sum_dim_intlist(1_i64, false, None::<Kind>)
                .mean_dim(0_i64, false, None::<Kind>);
        for b in 0..2 {
            let (e, m) = (scalar(&kept.get(b)), scalar(&mc_kept.get(b)));
            assert!((e - m).abs() < 0.02, "kept b={b}: {e} vs MC {m}");
            let (e, m) = (scalar(&changes.get(b)), scalar(&mc_changes.get(b)));
            assert!((e - m).abs() < 0.02, "changes b={b}: {e} vs MC {m}");
        }
    }
}
