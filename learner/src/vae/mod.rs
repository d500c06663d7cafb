//! The recurrent variational model with differentiable binary latent
//! variables that discovers pivotal states (Shang et al. 2019,
//! arXiv:1907.00664, section 3.1, Figure 2; the formulas are checked in
//! docs/latent-model-math.md).
//!
//! Given a trajectory `τ = {(s_t, a_t)}_{t=0..T}`, a binary latent `z_t`
//! decides whether `s_t` is kept for reconstructing the actions:
//!
//! - **prior** `p_ψ(z_t | s_t) = Beta(α_t, β_t)`, from the state alone
//!   ([`beta_prior`]); its mean is the *pivotality* of `s_t`;
//! - **posterior** `q_φ(z_t | a, s) = HardKuma(ã_t, 1)`, from a bidirectional
//!   LSTM over `(s_t, a_t)` ([`hardkuma`]); the boundary states are always
//!   kept, `z_0 = z_T = 1`;
//! - **decoder** `p_θ(a | s, z)`: a bidirectional LSTM over the states
//!   multiplied by `z_t` (so dropped states are invisible) that outputs a
//!   categorical distribution over each `a_t`;
//! - **objective** ([`elbo`]): action NLL + `λ1·KL + λ2·L0 + λ3·LT`, the
//!   multipliers ascending while the parameters descend.
//!
//! The pivotal states `V_p` are the top 20% of visited states by prior
//! mean ([`LatentModel::pivotal_states`]); the decoder's per-step action
//! reconstruction error is the curiosity bonus of `π_g` (section 3.2,
//! [`LatentModel::reconstruction_error`]).
//!
//! Threads: these networks are small, and libtorch's intra-op worker
//! threads cost more than they save on them, so the binary runs libtorch on
//! one thread by default (figures in `docs/implementation_details.md`,
//! "Learner throughput").
//!
//! ```no_run
//! use learner::vae::{AgentPose, LatentConfig, LatentTrainer, Trajectory, TrajectoryBatch};
//! # fn main() -> Result<(), learner::LearnerError> {
//! let cfg = LatentConfig { num_cells: 13 * 13, num_actions: 4, ..Default::default() };
//! let mut trainer = LatentTrainer::new(&cfg, tch::Device::Cpu, 0)?;
//! let walk = Trajectory {
//!     states: [14, 15, 16].map(AgentPose::at).to_vec(),
//!     actions: vec![0, 0],
//! };
//! let batch = TrajectoryBatch::new(&[walk], &cfg, tch::Device::Cpu)?;
//! let stats = trainer.train_step(&batch);
//! println!("nll {:.3}, kept {:.2}", stats.reconstruction_nll, stats.kept_fraction);
//! let pivotal = trainer.model().pivotal_states(&[14, 15, 16], 0.2);
//! # Ok(()) }
//! ```

pub mod batch;
pub mod beta_prior;
pub mod config;
pub mod elbo;
pub mod hardkuma;
pub mod recurrent;
pub mod state_encoder;

pub use batch::{AgentPose, Trajectory, TrajectoryBatch};
pub use beta_prior::BetaPrior;
pub use config::LatentConfig;
pub use elbo::{ElboTerms, LagrangeMultiplier, Multipliers};
pub use hardkuma::HardKuma;
pub use state_encoder::StateEncoder;

use std::collections::BTreeSet;

use rand::SeedableRng;
use rand::rngs::SmallRng;

use tch::nn::{self, Module, OptimizerConfig};
use tch::{Device, Kind, Tensor};

use crate::error::LearnerError;
use recurrent::BiLstm;

/// What one training step measured. Loss terms are per trajectory,
/// averaged over the batch.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LatentStats {
    /// The Lagrangian that was minimised.
    pub loss: f64,
    /// `−log p_θ(A | S, Z)` for one sample of `Z`.
    pub reconstruction_nll: f64,
    /// Fraction of actions reconstructed right (arg-max) with sampled `Z`.
    pub reconstruction_accuracy: f64,
    /// `KL(q ‖ p)` summed over interior states.
    pub kl: f64,
    /// `L0 = (E[‖Z‖₀] − μ0)²`, `μ0` per trajectory length.
    pub l0: f64,
    /// `LT = (E[#changes] − 2μ0 − 2)²` (the boundaries' two changes).
    pub transition: f64,
    /// `E[‖Z‖₀]`: expected kept interior states per trajectory.
    pub expected_kept: f64,
    /// Fraction of interior states with a sampled `z_t > 0`.
    pub kept_fraction: f64,
    /// `λ1` after this step's ascent.
    pub lambda_kl: f64,
    /// `λ2` after this step's ascent.
    pub lambda_l0: f64,
    /// `λ3` after this step's ascent.
    pub lambda_transition: f64,
}

/// Reconstruction quality with the evaluation-time latents
/// ([`HardKuma::decide`]), no sampling.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LatentEvaluation {
    /// Fraction of actions reconstructed right (arg-max).
    pub reconstruction_accuracy: f64,
    /// Mean `−log p_θ(a_t | S, Z)` per action.
    pub nll_per_action: f64,
    /// Fraction of interior states kept (`z_t > 0`).
    pub kept_fraction: f64,
}

/// `p_ψ(z_t | s_t) = Beta(α_t, β_t)`: a state encoder and an MLP.
#[derive(Debug)]
struct PriorNetwork {
    state: StateEncoder,
    hidden: nn::Linear,
    head: nn::Linear,
}

impl PriorNetwork {
    fn new(p: &nn::Path, cfg: &LatentConfig) -> Self {
        Self {
            state: StateEncoder::new(&(p / "state"), cfg),
            hidden: nn::linear(
                p / "hidden",
                cfg.state_dim,
                cfg.prior_hidden,
                Default::default(),
            ),
            head: nn::linear(p / "head", cfg.prior_hidden, 2, Default::default()),
        }
    }

    /// States as `[...]` int64 tensors; `α`, `β` of shape `[...]`.
    fn forward(&self, cells: &Tensor, directions: &Tensor, carried: &Tensor) -> BetaPrior {
        let features = self.state.forward(cells, directions, carried);
        let raw = self.head.forward(&self.hidden.forward(&features).relu());
        BetaPrior::from_raw(&raw.select(-1, 0), &raw.select(-1, 1))
    }
}

/// `q_φ(z_t | a, s) = HardKuma(ã_t, 1)`: a bidirectional LSTM over
/// `(s_t, a_t)`.
#[derive(Debug)]
struct PosteriorEncoder {
    state: StateEncoder,
    action: nn::Embedding,
    rnn: BiLstm,
    head: nn::Linear,
    no_action: i64,
}

impl PosteriorEncoder {
    fn new(p: &nn::Path, cfg: &LatentConfig) -> Self {
        // One extra action token for the last state, which takes no action.
        let action = nn::embedding(
            p / "action",
            cfg.num_actions + 1,
            cfg.action_dim,
            Default::default(),
        );
        Self {
            state: StateEncoder::new(&(p / "state"), cfg),
            action,
            rnn: BiLstm::new(
                &(p / "rnn"),
                cfg.state_dim + cfg.action_dim,
                cfg.lstm_hidden,
            ),
            head: nn::linear(p / "head", 2 * cfg.lstm_hidden, 1, Default::default()),
            no_action: cfg.num_actions,
        }
    }

    fn forward(&self, batch: &TrajectoryBatch) -> HardKuma {
        let states = self
            .state
            .forward(&batch.cells, &batch.directions, &batch.carried);
        let has_action = batch.action_mask.to_kind(Kind::Int64);
        let tokens = &batch.actions * &has_action + (1 - &has_action) * self.no_action;
        let input = Tensor::cat(&[states, self.action.forward(&tokens)], -1);
        let raw = self
            .head
            .forward(&self.rnn.seq(&input, batch))
            .squeeze_dim(-1);
        HardKuma::from_raw(&raw)
    }
}

/// `p_θ(a | s, z)`: a bidirectional LSTM over the kept states only.
#[derive(Debug)]
struct Decoder {
    state: StateEncoder,
    rnn: BiLstm,
    head: nn::Linear,
}

impl Decoder {
    fn new(p: &nn::Path, cfg: &LatentConfig) -> Self {
        Self {
            state: StateEncoder::new(&(p / "state"), cfg),
            rnn: BiLstm::new(&(p / "rnn"), cfg.state_dim, cfg.lstm_hidden),
            head: nn::linear(
                p / "head",
                2 * cfg.lstm_hidden,
                cfg.num_actions,
                Default::default(),
            ),
        }
    }

    /// `z`: `[L, B]`, zero on dropped states and padding. Returns action
    /// logits `[L, B, A]`.
    fn forward(&self, batch: &TrajectoryBatch, z: &Tensor) -> Tensor {
        let states = self
            .state
            .forward(&batch.cells, &batch.directions, &batch.carried);
        let kept = states * z.unsqueeze(-1);
        self.head.forward(&self.rnn.seq(&kept, batch))
    }
}

/// The latent model: prior, posterior encoder, decoder and the Lagrange
/// multipliers of its objective.
#[derive(Debug)]
pub struct LatentModel {
    prior: PriorNetwork,
    posterior: PosteriorEncoder,
    decoder: Decoder,
    multipliers: Multipliers,
    cfg: LatentConfig,
    device: Device,
    /// The posterior samples' noise (see [`crate::seeding`]).
    noise: SmallRng,
}

impl LatentModel {
    /// Builds the three networks under `p / "prior"`, `p / "posterior"` and
    /// `p / "decoder"`. `cfg` must have passed [`LatentConfig::validate`].
    /// The weights come from libtorch's generator (seed it, e.g. through
    /// [`crate::seeding::init_seeded`]); the posterior's sampling noise
    /// from `noise_seed`.
    pub fn new(p: &nn::Path, cfg: &LatentConfig, noise_seed: u64) -> Self {
        Self {
            noise: SmallRng::seed_from_u64(noise_seed),
            prior: PriorNetwork::new(&(p / "prior"), cfg),
            posterior: PosteriorEncoder::new(&(p / "posterior"), cfg),
            decoder: Decoder::new(&(p / "decoder"), cfg),
            multipliers: Multipliers::new(cfg),
            cfg: cfg.clone(),
            device: p.device(),
        }
    }

    /// The configuration the model was built with.
    pub fn config(&self) -> &LatentConfig {
        &self.cfg
    }

    /// The current Lagrange multipliers.
    pub fn multipliers(&self) -> &Multipliers {
        &self.multipliers
    }

    /// Restarts the posterior's sampling noise from `seed` (the discovery
    /// loop does so every round, so a resumed run draws what an
    /// uninterrupted one would have).
    pub fn reseed_noise(&mut self, seed: u64) {
        self.noise = SmallRng::seed_from_u64(seed);
    }

    /// Restores multipliers saved with a checkpoint.
    pub fn set_multipliers(&mut self, multipliers: Multipliers) {
        self.multipliers = multipliers;
    }

    /// The prior `Beta(α_t, β_t)` of every state of `batch` (`[L, B]` each).
    pub fn prior(&self, batch: &TrajectoryBatch) -> BetaPrior {
        self.prior
            .forward(&batch.cells, &batch.directions, &batch.carried)
    }

    /// The posterior `HardKuma(ã_t, 1)` of every state of `batch` (`[L, B]`).
    pub fn posterior(&self, batch: &TrajectoryBatch) -> HardKuma {
        self.posterior.forward(batch)
    }

    /// Latents fed to the decoder: 1 on boundaries, `z_t` (sampled, or the
    /// evaluation-time decision) on interior states, 0 on padding; `[L, B]`.
    fn latents(
        &self,
        posterior: &HardKuma,
        batch: &TrajectoryBatch,
        noise: Option<&mut SmallRng>,
    ) -> Tensor {
        let z = match noise {
            Some(rng) => posterior.rsample(rng),
            None => posterior.decide(),
        };
        &batch.boundary_mask + z * batch.interior_mask()
    }

    /// One sample of the objective's terms for `batch` (with gradients),
    /// the posterior sampled with `noise`.
    pub fn elbo_terms(&self, batch: &TrajectoryBatch, noise: &mut SmallRng) -> ElboTerms {
        let posterior = self.posterior(batch);
        let prior = self.prior(batch);
        let z = self.latents(&posterior, batch, Some(noise));
        let logits = self.decoder.forward(batch, &z);
        elbo::elbo_terms(
            &posterior,
            &prior,
            &z,
            &logits,
            batch,
            self.cfg.kept_per_step,
        )
    }

    /// One optimisation step: descend the Lagrangian
    /// `NLL + λ1·KL + λ2·L0 + λ3·LT` with `opt` (which must hold this
    /// model's variables), then one ascent step on the λs.
    pub fn train_step(&mut self, opt: &mut nn::Optimizer, batch: &TrajectoryBatch) -> LatentStats {
        let mut noise = self.noise.clone();
        let terms = self.elbo_terms(batch, &mut noise);
        self.noise = noise;
        let loss = self.multipliers.lagrangian(&terms);
        opt.backward_step_clip_norm(&loss, self.cfg.grad_clip_norm);
        let scalar = |t: &Tensor| t.double_value(&[]);
        let (kl, l0, transition) = (
            scalar(&terms.kl),
            scalar(&terms.l0),
            scalar(&terms.transition),
        );
        self.multipliers.ascend(kl, l0, transition, &self.cfg);
        LatentStats {
            loss: scalar(&loss),
            reconstruction_nll: scalar(&terms.reconstruction_nll),
            reconstruction_accuracy: terms.reconstruction_accuracy,
            kl,
            l0,
            transition,
            expected_kept: terms.expected_kept,
            kept_fraction: terms.kept_fraction,
            lambda_kl: self.multipliers.kl.value,
            lambda_l0: self.multipliers.l0.value,
            lambda_transition: self.multipliers.transition.value,
        }
    }

    /// Per-step action reconstruction error `−log p_θ(a_t | S, Z)` with the
    /// evaluation-time latents: `[L, B]`, zero where no action was taken.
    /// This is the curiosity bonus of `π_g` (section 3.2).
    pub fn reconstruction_error(&self, batch: &TrajectoryBatch) -> Tensor {
        tch::no_grad(|| {
            let z = self.latents(&self.posterior(batch), batch, None);
            elbo::action_nll(&self.decoder.forward(batch, &z), batch).0
        })
    }

    /// Reconstruction quality of `batch` with the evaluation-time latents.
    pub fn evaluate(&self, batch: &TrajectoryBatch) -> LatentEvaluation {
        tch::no_grad(|| {
            let z = self.latents(&self.posterior(batch), batch, None);
            let (nll, correct) = elbo::action_nll(&self.decoder.forward(batch, &z), batch);
            let sum = |t: &Tensor| t.sum(None::<Kind>).double_value(&[]);
            let actions = sum(&batch.action_mask).max(1.0);
            let interior = batch.interior_mask();
            LatentEvaluation {
                reconstruction_accuracy: sum(&correct) / actions,
                nll_per_action: sum(&nll) / actions,
                kept_fraction: sum(&(z.gt(0.0).to_kind(Kind::Float) * &interior))
                    / sum(&interior).max(1.0),
            }
        })
    }

    /// Prior means `α/(α+β)` of the given agent poses.
    pub fn prior_mean_of_poses(&self, poses: &[AgentPose]) -> Vec<f32> {
        if poses.is_empty() {
            return Vec::new();
        }
        let column = |f: fn(&AgentPose) -> i64| {
            Tensor::from_slice(&poses.iter().map(f).collect::<Vec<_>>()).to_device(self.device)
        };
        let cells = column(|p| i64::from(p.cell));
        let facings: Vec<i64> = poses
            .iter()
            .map(|p| self.cfg.facing_index(p.direction))
            .collect();
        let directions = Tensor::from_slice(&facings).to_device(self.device);
        let carried = column(|p| i64::from(p.carried));
        tch::no_grad(|| {
            let mean = self.prior.forward(&cells, &directions, &carried).mean();
            Vec::<f32>::try_from(mean.to_kind(Kind::Float).to_device(Device::Cpu))
                .expect("invariant: a 1-d float tensor converts to Vec<f32>")
        })
    }

    /// Pivotality of each cell: the prior mean `α/(α+β)` averaged over the
    /// agent's facing directions, carrying nothing.
    pub fn prior_mean(&self, cells: &[u32]) -> Vec<f32> {
        let dirs = u8::try_from(self.cfg.num_directions).unwrap_or(u8::MAX);
        let poses: Vec<AgentPose> = cells
            .iter()
            .flat_map(|&cell| {
                (0..dirs).map(move |direction| AgentPose {
                    cell,
                    direction,
                    carried: 0,
                })
            })
            .collect();
        let means = self.prior_mean_of_poses(&poses);
        means
            .chunks(usize::from(dirs).max(1))
            .map(|m| m.iter().sum::<f32>() / m.len() as f32)
            .collect()
    }

    /// The pivotal states `V_p`: the top `ratio` of the distinct `visited`
    /// cells ranked by [`LatentModel::prior_mean`] (the paper uses 0.2),
    /// at least one when any cell was visited; most pivotal first, ties
    /// broken by cell index.
    pub fn pivotal_states(&self, visited: &[u32], ratio: f64) -> Vec<u32> {
        let cells: Vec<u32> = visited
            .iter()
            .copied()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let means = self.prior_mean(&cells);
        planner::pivotal::top_ratio(cells.into_iter().zip(means).collect(), ratio)
    }

    /// Like [`LatentModel::pivotal_states`], but a cell's pivotality is the
    /// prior mean averaged over the distinct poses it was *visited* in, so
    /// directions or carried objects never seen there do not count.
    pub fn pivotal_states_of_poses(&self, visited: &[AgentPose], ratio: f64) -> Vec<u32> {
        let poses: Vec<AgentPose> = visited
            .iter()
            .copied()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let means = self.prior_mean_of_poses(&poses);
        let mut per_cell: std::collections::BTreeMap<u32, (f32, f32)> = Default::default();
        for (pose, mean) in poses.iter().zip(means) {
            let entry = per_cell.entry(pose.cell).or_default();
            *entry = (entry.0 + mean, entry.1 + 1.0);
        }
        planner::pivotal::top_ratio(
            per_cell
                .into_iter()
                .map(|(cell, (sum, n))| (cell, sum / n))
                .collect(),
            ratio,
        )
    }
}

/// A [`LatentModel`] with its own variable store and Adam optimiser.
pub struct LatentTrainer {
    vs: nn::VarStore,
    model: LatentModel,
    opt: nn::Optimizer,
}

impl std::fmt::Debug for LatentTrainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LatentTrainer")
            .field("model", &self.model)
            .finish_non_exhaustive()
    }
}

impl LatentTrainer {
    /// Validates `cfg`, builds the model on `device` with weights and
    /// sampling noise from `seed`, and an Adam optimiser at
    /// `cfg.learning_rate`.
    pub fn new(cfg: &LatentConfig, device: Device, seed: u64) -> Result<Self, LearnerError> {
        cfg.validate()?;
        let (vs, model) = crate::seeding::init_seeded(seed, || {
            let vs = nn::VarStore::new(device);
            let model = LatentModel::new(&vs.root(), cfg, seed);
            (vs, model)
        });
        let opt = nn::Adam::default().build(&vs, cfg.learning_rate)?;
        Ok(Self { vs, model, opt })
    }

    /// A fresh Adam optimiser (moments are not part of a checkpoint; the
    /// discovery loop starts every round with one, so resuming repeats an
    /// uninterrupted run).
    pub fn reset_optimizer(&mut self) -> Result<(), LearnerError> {
        self.opt = nn::Adam::default().build(&self.vs, self.model.cfg.learning_rate)?;
        Ok(())
    }

    /// One step of [`LatentModel::train_step`].
    pub fn train_step(&mut self, batch: &TrajectoryBatch) -> LatentStats {
        self.model.train_step(&mut self.opt, batch)
    }

    /// The model being trained.
    pub fn model(&self) -> &LatentModel {
        &self.model
    }

    /// Mutable access to the model (e.g. to restore its multipliers).
    pub fn model_mut(&mut self) -> &mut LatentModel {
        &mut self.model
    }

    /// The variables, e.g. to save or load a checkpoint.
    pub fn var_store(&self) -> &nn::VarStore {
        &self.vs
    }

    /// Mutable access to the variables (for `VarStore::load`).
    pub fn var_store_mut(&mut self) -> &mut nn::VarStore {
        &mut self.vs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> LatentConfig {
        LatentConfig {
            num_cells: 16,
            num_actions: 4,
            lstm_hidden: 16,
            state_dim: 8,
            ..Default::default()
        }
    }

    fn walks() -> Vec<Trajectory> {
        let walk = |cells: &[u32], actions: &[u8]| Trajectory {
            states: cells.iter().map(|&c| AgentPose::at(c)).collect(),
            actions: actions.to_vec(),
        };
        vec![
            walk(&[0, 1, 2, 3, 7, 11], &[0, 0, 0, 1, 1]),
            walk(&[5, 9], &[1]),
            walk(&[15, 14, 10], &[2, 3]),
        ]
    }

    #[test]
    fn padding_does_not_change_a_trajectorys_outputs() {
        let cfg = cfg();
        let trainer = LatentTrainer::new(&cfg, Device::Cpu, 1).expect("model builds");
        let model = trainer.model();
        let trajectories = walks();
        let alone = TrajectoryBatch::new(&trajectories[1..2], &cfg, Device::Cpu).expect("batch");
        let padded = TrajectoryBatch::new(&trajectories, &cfg, Device::Cpu).expect("batch");
        let a_alone = model.posterior(&alone).a.select(1, 0);
        let a_padded = model.posterior(&padded).a.select(1, 1).narrow(0, 0, 2);
        let gap = (a_alone - a_padded).abs().max().double_value(&[]);
        assert!(gap < 1e-6, "posterior depends on padding: {gap}");
        let err_alone = model.reconstruction_error(&alone).select(1, 0);
        let err_padded = model.reconstruction_error(&padded).select(1, 1);
        assert!(
            (err_alone.get(0).double_value(&[]) - err_padded.get(0).double_value(&[])).abs() < 1e-5
        );
        for t in 1..6 {
            assert_eq!(
                err_padded.get(t).double_value(&[]),
                0.0,
                "no error without an action (t = {t})"
            );
        }
    }

    #[test]
    fn training_step_reports_finite_terms_and_moves_the_multipliers() {
        let cfg = cfg();
        let mut trainer = LatentTrainer::new(&cfg, Device::Cpu, 2).expect("model builds");
        let batch = TrajectoryBatch::new(&walks(), &cfg, Device::Cpu).expect("batch");
        let first = trainer.train_step(&batch);
        let mut last = first;
        for _ in 0..30 {
            last = trainer.train_step(&batch);
        }
        for value in [
            last.loss,
            last.reconstruction_nll,
            last.kl,
            last.l0,
            last.transition,
        ] {
            assert!(value.is_finite(), "{last:?}");
        }
        assert!((0.0..=1.0).contains(&last.kept_fraction));
        assert!(
            last.reconstruction_nll < first.reconstruction_nll,
            "{first:?} → {last:?}"
        );
        assert_ne!(last.lambda_l0, cfg.lambda_init, "λ2 ascends");
    }

    #[test]
    fn pivotal_states_are_the_top_ratio_of_distinct_visited_cells() {
        let cfg = cfg();
        let trainer = LatentTrainer::new(&cfg, Device::Cpu, 3).expect("model builds");
        let model = trainer.model();
        let visited: Vec<u32> = (0..10).chain(0..10).collect();
        let pivotal = model.pivotal_states(&visited, 0.2);
        assert_eq!(pivotal.len(), 2);
        let means = model.prior_mean(&(0..10).collect::<Vec<_>>());
        let threshold = means[pivotal[1] as usize];
        assert!(means.iter().filter(|&&m| m > threshold).count() <= 1);
        assert!(model.pivotal_states(&[], 0.2).is_empty());
        assert_eq!(model.pivotal_states(&[3], 0.2), vec![3]);

        // Pose-based ranking: a cell's score is the mean over its visited poses.
        let poses: Vec<AgentPose> = (0..10)
            .map(|cell| AgentPose {
                cell,
                direction: (cell % 4) as u8,
                carried: 0,
            })
            .collect();
        let by_pose = model.pivotal_states_of_poses(&poses, 0.2);
        let pose_means = model.prior_mean_of_poses(&poses);
        let mut expected: Vec<u32> = (0..10).collect();
        expected.sort_by(|&x, &y| {
            pose_means[y as usize]
                .total_cmp(&pose_means[x as usize])
                .then(x.cmp(&y))
        });
        assert_eq!(by_pose, expected[..2].to_vec());
    }
}
