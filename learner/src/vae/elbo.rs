//! The objective of the pivotal-state latent model and its Lagrangian
//! relaxation (Shang et al. 2019, arXiv:1907.00664, section 3.1, Eqs. 1–3):
//!
//! ```text
//! max_λ min_{θ,φ,ψ}  −E_q[log p_θ(A | S, Z)] + λ1·KL(q_φ ‖ p_ψ) + λ2·L0 + λ3·LT
//! L0 = (E_q[Σ_t 1{z_t ≠ 0}] − μ0)²
//! LT = (E_q[Σ_t 1{z_t ≠ z_{t+1}}] − 2·μ0 − 2)²
//! ```
//!
//! `μ0` is per trajectory, proportional to its length ("`μ0` of activated
//! `z_t = 1` given a sequence of length `T`"): `μ0 = kept_per_step · (T − 1)`
//! over its `T − 1` interior states ([`LatentConfig::kept_per_step`]). The
//! transition count runs over the whole trajectory, boundaries included, so
//! `μ0` isolated kept interior states make `2·μ0 + 2` changes: the `+ 2`
//! keeps L0 and LT from asking for different numbers of kept states.
//!
//! Every term is a per-trajectory quantity averaged over the batch; padding
//! never counts. The boundary latents are fixed (`z_0 = z_T = 1`), so the KL
//! and L0 run over the interior states, and the transition count sees the
//! boundaries as certain ones. The multipliers follow the stable update of
//! docs/latent-model-math.md ("Lagrangian relaxation").
//!
//! **Prior fit at unit weight.** The prior `ψ` enters only the KL, so
//! `argmin_ψ λ1·KL = argmin_ψ KL` for any `λ1 > 0`: the multiplier rescales
//! ψ's gradient without moving its optimum. Because `λ1` can swing by orders
//! of magnitude while it ascends, and Adam's second-moment memory then
//! stalls the prior for hundreds of steps, the Lagrangian here splits the
//! KL into `λ1·KL(q_φ ‖ sg(p_ψ))`, which regularises the posterior, and
//! `KL(sg(q_φ) ‖ p_ψ)`, which fits the prior (`sg` = stop-gradient). Both have
//! the value of the paper's KL; only their gradients are routed apart.

use tch::{Kind, Tensor};

use super::batch::TrajectoryBatch;
use super::beta_prior::BetaPrior;
use super::config::LatentConfig;
use super::hardkuma::{self, HardKuma};

/// The terms of the objective for one batch, each a scalar tensor
/// (per trajectory, averaged over the batch) that carries gradients.
#[derive(Debug)]
pub struct ElboTerms {
    /// `−E_q[log p_θ(A | S, Z)]`, one sample of `Z`.
    pub reconstruction_nll: Tensor,
    /// `Σ_t KL(Kuma(ã_t, 1) ‖ Beta(α_t, β_t))` over interior states, with
    /// the prior held fixed (gradients reach the posterior only).
    pub kl: Tensor,
    /// The same KL with the posterior held fixed (gradients reach the
    /// prior only): the prior's fitting loss.
    pub prior_fit: Tensor,
    /// `L0 = (E_q[‖Z‖₀] − μ0)²`.
    pub l0: Tensor,
    /// `LT = (E_q[#changes] − 2·μ0 − 2)²`.
    pub transition: Tensor,
    /// `E_q[‖Z‖₀]`, the expected number of kept interior states (no grad).
    pub expected_kept: f64,
    /// Fraction of interior states with a sampled `z_t > 0`.
    pub kept_fraction: f64,
    /// Fraction of actions whose most likely reconstruction is right.
    pub reconstruction_accuracy: f64,
}

/// Sums `x` (`[L, B]`) over time under `mask` and averages over the batch.
fn per_trajectory_mean(x: &Tensor, mask: &Tensor) -> Tensor {
    (x * mask)
        .sum_dim_intlist(0_i64, false, None::<Kind>)
        .mean(None::<Kind>)
}

/// The action log-likelihood terms: per-step NLL `−log p_θ(a_t | S, Z)`
/// (`[L, B]`, zero where no action was taken) and the per-step correctness
/// of the arg-max action (`[L, B]` float, zero likewise).
///
/// `logits`: `[L, B, A]` decoder outputs.
pub fn action_nll(logits: &Tensor, batch: &TrajectoryBatch) -> (Tensor, Tensor) {
    let log_probs = logits.log_softmax(-1, Kind::Float);
    let taken = batch.actions.unsqueeze(-1);
    let nll = -log_probs.gather(-1, &taken, false).squeeze_dim(-1) * &batch.action_mask;
    let correct = log_probs
        .argmax(-1, false)
        .eq_tensor(&batch.actions)
        .to_kind(Kind::Float)
        * &batch.action_mask;
    (nll, correct)
}

/// Assembles [`ElboTerms`]:
///
/// - `posterior`: `HardKuma(ã_t, 1)` with `ã` of shape `[L, B]`;
/// - `prior`: `Beta(α_t, β_t)`, each `[L, B]`;
/// - `z`: the sampled latents fed to the decoder, `[L, B]` (boundaries 1);
/// - `logits`: decoder outputs `[L, B, A]`;
/// - `kept_per_step`: `μ0 / (T − 1)`, see the module docs.
pub fn elbo_terms(
    posterior: &HardKuma,
    prior: &BetaPrior,
    z: &Tensor,
    logits: &Tensor,
    batch: &TrajectoryBatch,
    kept_per_step: f64,
) -> ElboTerms {
    let interior = batch.interior_mask();
    let (nll, correct) = action_nll(logits, batch);
    let reconstruction_nll = per_trajectory_mean(&nll, &batch.state_mask);
    let fixed_prior = BetaPrior::new(prior.alpha.detach(), prior.beta.detach());
    let kl = per_trajectory_mean(&fixed_prior.kl_from_kuma(&posterior.a), &interior);
    let prior_fit = per_trajectory_mean(&prior.kl_from_kuma(&posterior.a.detach()), &interior);

    // P(z_t = 0) with the boundary latents certain to be 1.
    let prob_zero = posterior.prob_zero() * &interior;
    let kept = hardkuma::expected_nonzero(&prob_zero, &interior);
    let changes = hardkuma::expected_transitions(&prob_zero, &batch.state_mask);
    // μ0 of each trajectory, `[B]`, and the changes its boundaries add
    // (two when it has an interior state).
    let interior_states = interior.sum_dim_intlist(0_i64, false, None::<Kind>);
    let mu0 = &interior_states * kept_per_step;
    let boundary_changes = interior_states.clamp_max(1.0) * 2.0;
    let l0 = (&kept - &mu0).square().mean(None::<Kind>);
    let transition = (changes - mu0 * 2.0 - boundary_changes)
        .square()
        .mean(None::<Kind>);

    let interior_count = interior.sum(None::<Kind>).double_value(&[]).max(1.0);
    let action_count = batch
        .action_mask
        .sum(None::<Kind>)
        .double_value(&[])
        .max(1.0);
    let sampled_kept = (z.gt(0.0).to_kind(Kind::Float) * &interior)
        .sum(None::<Kind>)
        .double_value(&[]);
    ElboTerms {
        reconstruction_nll,
        kl,
        prior_fit,
        l0,
        transition,
        expected_kept: kept.mean(None::<Kind>).double_value(&[]),
        kept_fraction: sampled_kept / interior_count,
        reconstruction_accuracy: correct.sum(None::<Kind>).double_value(&[]) / action_count,
    }
}

/// One Lagrange multiplier `λ ≥ 0` for a constraint `c = L − tolerance ≤ 0`.
///
/// Ascent step (notes, after the HardKuma authors' code): keep a moving
/// average `c̄ ← d·c̄ + (1 − d)·c`, then `λ ← clamp(λ·exp(η·c̄), λ_min, λ_max)`.
/// `λ` grows while the constraint is violated on average and shrinks once
/// it holds, so it settles where the constraint is just met.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LagrangeMultiplier {
    /// Current value of `λ`.
    pub value: f64,
    /// Moving average `c̄` of the constraint value.
    pub constraint_average: f64,
    tolerance: f64,
    seen: bool,
}

impl LagrangeMultiplier {
    /// A multiplier at `cfg.lambda_init` for the constraint `L ≤ tolerance`.
    pub fn new(cfg: &LatentConfig, tolerance: f64) -> Self {
        Self {
            value: cfg.lambda_init,
            constraint_average: 0.0,
            tolerance,
            seen: false,
        }
    }

    /// One ascent step after observing the regulariser value `term`.
    pub fn ascend(&mut self, term: f64, cfg: &LatentConfig) {
        let constraint = term - self.tolerance;
        self.constraint_average = if self.seen {
            cfg.constraint_decay * self.constraint_average
                + (1.0 - cfg.constraint_decay) * constraint
        } else {
            constraint
        };
        self.seen = true;
        let grown = self.value * (cfg.lagrange_lr * self.constraint_average).exp();
        self.value = grown.clamp(cfg.lambda_min, cfg.lambda_max);
    }
}

/// `λ1` (KL), `λ2` (L0), `λ3` (transitions). Serialisable, so a checkpoint
/// can keep them next to the network weights.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Multipliers {
    /// `λ1`, weight of the KL term.
    pub kl: LagrangeMultiplier,
    /// `λ2`, weight of L0.
    pub l0: LagrangeMultiplier,
    /// `λ3`, weight of LT.
    pub transition: LagrangeMultiplier,
}

impl Multipliers {
    /// All three at `cfg.lambda_init`, with the tolerances of `cfg`.
    pub fn new(cfg: &LatentConfig) -> Self {
        Self {
            kl: LagrangeMultiplier::new(cfg, cfg.kl_budget),
            l0: LagrangeMultiplier::new(cfg, cfg.l0_tolerance),
            transition: LagrangeMultiplier::new(cfg, cfg.transition_tolerance),
        }
    }

    /// The Lagrangian `NLL + λ1·KL + λ2·L0 + λ3·LT` (λ held constant),
    /// plus the prior's unit-weight fit (module docs).
    pub fn lagrangian(&self, terms: &ElboTerms) -> Tensor {
        &terms.reconstruction_nll
            + &terms.prior_fit
            + &terms.kl * self.kl.value
            + &terms.l0 * self.l0.value
            + &terms.transition * self.transition.value
    }

    /// Ascent on every multiplier from the observed regulariser values.
    pub fn ascend(&mut self, kl: f64, l0: f64, transition: f64, cfg: &LatentConfig) {
        self.kl.ascend(kl, cfg);
        self.l0.ascend(l0, cfg);
        self.transition.ascend(transition, cfg);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multiplier_grows_under_violation_and_shrinks_once_met() {
        let cfg = LatentConfig::default();
        let mut lambda = LagrangeMultiplier::new(&cfg, 1.0);
        for _ in 0..50 {
            lambda.ascend(5.0, &cfg);
        }
        let grown = lambda.value;
        assert!(grown > cfg.lambda_init * 100.0, "λ = {grown}");
        assert!(grown <= cfg.lambda_max);
        for _ in 0..50 {
            lambda.ascend(0.0, &cfg);
        }
        assert!(
            lambda.value < grown,
            "λ = {} after the constraint holds",
            lambda.value
        );
        for _ in 0..5000 {
            lambda.ascend(0.0, &cfg);
        }
        assert_eq!(lambda.value, cfg.lambda_min);
    }
}
