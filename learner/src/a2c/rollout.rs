//! Rollout storage and the A2C update of an agent that acts at every
//! environment step (`π_g`, the A2C baseline, the Worker).
//!
//! A rollout holds `T` steps of `B` environments, entry `t·B + b`, plus the
//! core state it started from and the bootstrap values `V(s_T)` `[B]` (the
//! `+1` of CleanRL's `[T + 1, B]` layout). Three ways to fill it, chosen by
//! [`GradPath`]:
//!
//! - [`GradPath::Recompute`]: each step runs the network under
//!   `no_grad` on a [`CellInput`] and appends that input; the update
//!   re-encodes all `T·B` observations in one batched call, unrolls the
//!   LSTM over the stored features from the stored initial state (resetting
//!   where an episode ended), and applies the heads to all `T·B` core
//!   outputs at once;
//! - [`GradPath::PerStep`]: each step runs the network with autograd
//!   (first layer by gather-and-sum) and keeps its logits and value; the
//!   update back-propagates through those graphs;
//! - [`GradPath::Plain`]: the same with the dense first convolution over
//!   one-hot planes (the benchmark's baseline);
//! - [`GradPath::RustEncoder`]: the encoder in the project's own kernels
//!   outside the graph, each step's features a leaf of its graph (the core
//!   and heads), the encoder's backward run once over the whole rollout
//!   ([`crate::a2c::encoder`]);
//! - [`GradPath::RustCore`] (the default): the whole network in the own
//!   kernels, no graph while acting; the loss in tch over the rollout's
//!   logits and values, the rest of the backward (through time) in the own
//!   kernels ([`crate::a2c::rust_net`]).
//!
//! All five give the same loss and gradients for the same rollout (tests
//! check it). Which is fastest is measured by `worldgraph bench learner`:
//! with these small networks on a CPU the update is compute-bound, so the
//! recomputation's second forward pass costs more than batching saves,
//! and the own kernels' GEMM outruns libtorch's at these shapes
//! (`docs/notes/2026-12-01-learner-throughput.md`).

use tch::{Kind, Tensor, nn};

use super::encoder::{RustEncoder, with_gradients};
pub use super::grad_path::GradPath;
use super::input::{CellInput, GoalMarks, encode_obs, goal_planes};
use super::net::{ActorCritic, ActorCriticOutput, LstmState};
use super::rust_net::RustActorCritic;
use super::tensors::floats;
use super::{A2cConfig, Categorical, LossFigures, PhaseTimes, PolicyTerms, a2c_loss, advantages};
use crate::batch_env::ObsView;

/// One rollout of an every-step agent.
#[derive(Debug)]
pub struct Rollout {
    path: GradPath,
    num_envs: usize,
    /// Observations of the steps (recompute path).
    inputs: CellInput,
    /// Logits and values of every step with their graphs (per-step path).
    graph_logits: Vec<Tensor>,
    graph_values: Vec<Tensor>,
    /// The encoder of the own kernels and its activations (rust-encoder
    /// path; behind a lock because [`Self::loss`] runs its backward
    /// through `&self`).
    encoder: std::sync::Mutex<Option<RustEncoder>>,
    /// The whole network in the own kernels and its activations (rust-core
    /// path; locked for the same reason).
    own_net: std::sync::Mutex<Option<RustActorCritic>>,
    /// Whether the encoder's (or the own network's) weights are to be re-read before the next
    /// step (set by [`Self::start`]: an update may have changed them).
    encoder_stale: bool,
    /// Every step's features, the leaves of its graph (rust-encoder path).
    leaves: Vec<Tensor>,
    /// Actions `[T·B]`.
    pub actions: Vec<i64>,
    /// Rewards `[T·B]`.
    pub rewards: Vec<f32>,
    /// 1 where the step ended the agent's episode (the core is reset before
    /// the next step).
    pub dones: Vec<f32>,
    /// `V(s_t)` as computed while acting `[T·B]`.
    pub values: Vec<f32>,
    /// 1 where the agent chose the step's action; 0 leaves the step out of
    /// the loss (a Worker's step taken by graph traversal).
    pub weights: Vec<f32>,
    /// `V(s_T)` `[B]`.
    pub bootstrap: Vec<f32>,
    /// The core state before the first step.
    init_state: Option<LstmState>,
    /// Time spent encoding, acting and updating (the caller adds its own
    /// stepping time).
    pub times: PhaseTimes,
}

impl Rollout {
    /// An empty rollout of `num_envs` environments on `width × height`
    /// grids.
    pub fn new(
        path: GradPath,
        num_envs: usize,
        width: usize,
        height: usize,
        goal_planes: usize,
    ) -> Rollout {
        Rollout {
            path,
            num_envs,
            inputs: CellInput::new(width, height, goal_planes),
            graph_logits: Vec::new(),
            graph_values: Vec::new(),
            encoder: std::sync::Mutex::new(None),
            own_net: std::sync::Mutex::new(None),
            encoder_stale: true,
            leaves: Vec::new(),
            actions: Vec::new(),
            rewards: Vec::new(),
            dones: Vec::new(),
            values: Vec::new(),
            weights: Vec::new(),
            bootstrap: Vec::new(),
            init_state: None,
            times: PhaseTimes::default(),
        }
    }

    /// The gradient path.
    pub fn path(&self) -> GradPath {
        self.path
    }

    /// Steps stored.
    pub fn steps(&self) -> usize {
        self.actions.len() / self.num_envs.max(1)
    }

    /// Empties the rollout and records the core state the next one starts
    /// from.
    pub fn start(&mut self, state: &LstmState) {
        self.inputs.clear();
        self.graph_logits.clear();
        self.graph_values.clear();
        self.leaves.clear();
        self.encoder_stale = true;
        self.actions.clear();
        self.rewards.clear();
        self.dones.clear();
        self.values.clear();
        self.weights.clear();
        self.bootstrap.clear();
        self.init_state = Some(state.detach());
    }

    /// One step of `net` on `obs` from `state`, recorded for the update:
    /// under `no_grad` on the fast input (recompute path), or with autograd
    /// on the dense input (per-step path). The returned logits carry no
    /// graph in either case.
    pub fn act(
        &mut self,
        net: &ActorCritic,
        obs: &ObsView<'_>,
        goals: Option<GoalMarks<'_>>,
        state: &LstmState,
    ) -> ActorCriticOutput {
        let t0 = std::time::Instant::now();
        match self.path {
            GradPath::Recompute => {
                let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
                input.push_obs(obs, goals);
                self.inputs.extend_from(&input);
                let t1 = PhaseTimes::lap(&mut self.times.encode, t0);
                let out = tch::no_grad(|| net.step(&input, state));
                self.values.extend(floats(&out.value));
                PhaseTimes::lap(&mut self.times.act, t1);
                out
            }
            GradPath::RustEncoder => {
                let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
                input.push_obs(obs, goals);
                let t1 = PhaseTimes::lap(&mut self.times.encode, t0);
                let encoder = current(
                    &mut self.encoder,
                    std::mem::take(&mut self.encoder_stale),
                    || RustEncoder::new(net.trunk()),
                    |e| e.load(net.trunk()),
                );
                let features = encoder.forward(&input).set_requires_grad(true);
                let out = net.step_features(&features, state);
                self.leaves.push(features);
                self.keep_graph(out, t1)
            }
            GradPath::RustCore => {
                let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
                input.push_obs(obs, goals);
                let t1 = PhaseTimes::lap(&mut self.times.encode, t0);
                let own = current(
                    &mut self.own_net,
                    std::mem::take(&mut self.encoder_stale),
                    || RustActorCritic::new(net),
                    |own| own.load(net),
                );
                let out = own.step(&input, state);
                self.values.extend(floats(&out.value));
                PhaseTimes::lap(&mut self.times.act, t1);
                out
            }
            GradPath::PerStep | GradPath::Plain => {
                let (x, input) = if self.path == GradPath::Plain {
                    (Some(encode_obs(obs, goals)), None)
                } else {
                    let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
                    input.push_obs(obs, goals);
                    (None, Some(input))
                };
                let t1 = PhaseTimes::lap(&mut self.times.encode, t0);
                let out = match (&x, &input) {
                    (Some(x), _) => net.forward(x, state),
                    (_, Some(input)) => net.step(input, state),
                    _ => unreachable!("one of the two inputs is built"),
                };
                self.keep_graph(out, t1)
            }
        }
    }

    /// Keeps the step's graph (its logits and value) for the update and
    /// returns the step's output detached from it; `t1`: when acting began.
    fn keep_graph(&mut self, out: ActorCriticOutput, t1: std::time::Instant) -> ActorCriticOutput {
        self.values.extend(floats(&out.value.detach()));
        PhaseTimes::lap(&mut self.times.act, t1);
        self.graph_logits.push(out.logits.shallow_clone());
        self.graph_values.push(out.value.shallow_clone());
        ActorCriticOutput {
            logits: out.logits.detach(),
            value: out.value.detach(),
            state: out.state,
        }
    }

    /// Books the outcome of a step's actions for every environment.
    pub fn record(&mut self, actions: &[u8], rewards: &[f32], dones: &[bool], weights: &[f32]) {
        self.actions.extend(actions.iter().map(|&a| i64::from(a)));
        self.rewards.extend_from_slice(rewards);
        self.dones
            .extend(dones.iter().map(|&d| f32::from(u8::from(d))));
        self.weights.extend_from_slice(weights);
    }

    /// Adds `bonus[t·B + b]` to the rewards (the curiosity of `π_g`).
    pub fn add_to_rewards(&mut self, bonus: &[f32]) {
        for (r, b) in self.rewards.iter_mut().zip(bonus) {
            *r += b;
        }
    }

    /// The update's loss and its figures: GAE over the rollout with
    /// discount `γ · (1 − done)`, then [`a2c_loss`].
    pub fn loss(&self, net: &ActorCritic, cfg: &A2cConfig) -> (Tensor, LossFigures) {
        let (steps, b) = (self.steps() as i64, self.num_envs as i64);
        let (logits, values) = match self.path {
            GradPath::Recompute => {
                let trunk = net.trunk();
                let features = trunk.features(&self.inputs).view([steps, b, -1]);
                // The core is reset before step t where step t − 1 ended an
                // episode; the initial state was reset by the caller.
                let mut reset = vec![0f32; self.dones.len()];
                reset[self.num_envs..]
                    .copy_from_slice(&self.dones[..self.dones.len() - self.num_envs]);
                let reset = Tensor::from_slice(&reset).view([steps, b]);
                let init = self
                    .init_state
                    .as_ref()
                    .expect("invariant: start() before loss()");
                let (hs, _) = trunk.unroll(&features, init, &reset);
                let (logits, values) = net.heads(&hs.view([steps * b, -1]));
                (logits, values)
            }
            GradPath::PerStep | GradPath::Plain | GradPath::RustEncoder => (
                Tensor::cat(&self.graph_logits, 0),
                Tensor::cat(&self.graph_values, 0),
            ),
            GradPath::RustCore => {
                let slot = self
                    .own_net
                    .lock()
                    .unwrap_or_else(|poisoned| poisoned.into_inner());
                let own = slot
                    .as_ref()
                    .expect("invariant: the rust-core path ran the rollout's steps");
                (
                    Tensor::from_slice(own.logits())
                        .view([steps * b, -1])
                        .set_requires_grad(true),
                    Tensor::from_slice(&self.values).set_requires_grad(true),
                )
            }
        };
        let gamma = cfg.gamma as f32;
        let discounts: Vec<f32> = self.dones.iter().map(|&d| gamma * (1.0 - d)).collect();
        let (adv, ret) = advantages(
            &self.rewards,
            &self.values,
            &discounts,
            &self.bootstrap,
            cfg.gae_lambda as f32,
        );
        let pi = Categorical::new(&logits, None);
        let terms = PolicyTerms {
            log_prob: pi.log_prob(&Tensor::from_slice(&self.actions)),
            entropy: pi.entropy(),
            value: values.to_kind(Kind::Float),
        };
        let (loss, figures) = a2c_loss(&terms, &adv, &ret, &self.weights, cfg);
        if self.path == GradPath::RustEncoder {
            return (self.encoder_backward(net, &loss), figures);
        }
        if self.path == GradPath::RustCore {
            let mut slot = self
                .own_net
                .lock()
                .unwrap_or_else(|poisoned| poisoned.into_inner());
            let own = slot
                .as_mut()
                .expect("invariant: the rust-core path ran the rollout's steps");
            let loss = super::rust_net::backward(own, net, &loss, &logits, &values);
            return (loss, figures);
        }
        (loss, figures)
    }

    /// The rust-encoder path's backward: back-propagates `loss` through the
    /// steps' graphs to their feature leaves and to the core's and heads'
    /// parameters, then runs the encoder's backward over the whole rollout;
    /// returns the loss whose `backward` hands all these gradients to the
    /// caller's optimiser ([`with_gradients`]).
    fn encoder_backward(&self, net: &ActorCritic, loss: &Tensor) -> Tensor {
        let trunk = net.trunk();
        let rest: Vec<Tensor> = trunk
            .core_parameters()
            .into_iter()
            .chain(net.head_parameters())
            .filter(Tensor::requires_grad)
            .collect();
        let inputs: Vec<&Tensor> = self.leaves.iter().chain(&rest).collect();
        let grads = Tensor::run_backward(&[loss], &inputs, false, false);
        let (leaf_grads, rest_grads) = grads.split_at(self.leaves.len());
        let dfeatures: Vec<Tensor> = leaf_grads
            .iter()
            .zip(&self.leaves)
            .map(|(g, leaf)| {
                if g.defined() {
                    g.shallow_clone()
                } else {
                    leaf.zeros_like()
                }
            })
            .collect();
        let dfeatures = floats(&Tensor::cat(&dfeatures, 0));
        let mut slot = self
            .encoder
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let encoder = slot
            .as_mut()
            .expect("invariant: the rust-encoder path encoded the rollout's steps");
        let encoder_grads = encoder.backward(&dfeatures);
        let params: Vec<Tensor> = trunk.encoder_parameters().into_iter().chain(rest).collect();
        let grads: Vec<Tensor> = encoder_grads
            .into_iter()
            .chain(rest_grads.iter().map(Tensor::shallow_clone))
            .collect();
        with_gradients(loss, &params, &grads)
    }

    /// The update: [`Self::loss`], then one clipped Adam step.
    pub fn update(
        &mut self,
        net: &ActorCritic,
        opt: &mut nn::Optimizer,
        cfg: &A2cConfig,
    ) -> LossFigures {
        let t0 = std::time::Instant::now();
        let (loss, figures) = self.loss(net, cfg);
        let t1 = PhaseTimes::lap(&mut self.times.loss, t0);
        opt.backward_step_clip_norm(&loss, cfg.grad_clip_norm);
        PhaseTimes::lap(&mut self.times.backward, t1);
        figures
    }
}

/// The own-kernel network in `slot` with the weights of the network it
/// mirrors: built by `new` the first time, re-read by `load` when `stale`
/// (an update may have changed the weights since the last step).
fn current<T>(
    slot: &mut std::sync::Mutex<Option<T>>,
    stale: bool,
    new: impl FnOnce() -> T,
    load: impl FnOnce(&mut T),
) -> &mut T {
    let slot = slot
        .get_mut()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    match slot {
        Some(own) => {
            if stale {
                load(own);
            }
            own
        }
        None => slot.insert(new()),
    }
}

/// The value of `net` at `obs` from `state`, without gradient (the
/// bootstrap `V(s_T)`).
pub fn bootstrap_values(
    net: &ActorCritic,
    obs: &ObsView<'_>,
    goals: Option<GoalMarks<'_>>,
    state: &LstmState,
) -> Vec<f32> {
    let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
    input.push_obs(obs, goals);
    floats(&tch::no_grad(|| net.step(&input, state).value))
}

/// The values `V(s_final)` of the final states of environments `envs`,
/// whose episodes were *truncated* by the step that produced `obs`, from
/// `state` (the core state after that step, `[B, hidden]`, before any
/// reset), without gradient. Truncation is not termination: the step's
/// return goes on past the step limit, so its target is `r + γ·V(s_final)`
/// (Gymnasium's `final_obs`; the step is then booked as done, see
/// [`bootstrap_truncated`]).
pub fn final_values(
    net: &ActorCritic,
    obs: &ObsView<'_>,
    goals: Option<GoalMarks<'_>>,
    state: &LstmState,
    envs: &[usize],
) -> Vec<f32> {
    if envs.is_empty() {
        return Vec::new();
    }
    let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
    for &e in envs {
        input.push_final_env(obs, e, goals);
    }
    let idx = Tensor::from_slice(&envs.iter().map(|&e| e as i64).collect::<Vec<_>>());
    floats(&tch::no_grad(|| {
        net.step(&input, &state.select(&idx)).value
    }))
}

/// Adds `γ·V(s_final)` to the rewards of the environments `envs` whose
/// episode the step truncated ([`final_values`]); their `done` stays set,
/// so nothing is bootstrapped from the next episode's first state.
#[allow(clippy::too_many_arguments)]
pub fn bootstrap_truncated(
    rewards: &mut [f32],
    net: &ActorCritic,
    obs: &ObsView<'_>,
    goals: Option<GoalMarks<'_>>,
    state: &LstmState,
    envs: &[usize],
    gamma: f64,
) {
    for (&e, v) in envs.iter().zip(final_values(net, obs, goals, state, envs)) {
        rewards[e] += gamma as f32 * v;
    }
}

#[cfg(test)]
mod tests {
    use rand::rngs::SmallRng;
    use rand::{Rng, SeedableRng};
    use sim::{EnvConfig, Layout, Maze, Task};

    use super::*;
    use crate::a2c::input::mask;
    use crate::a2c::net::ActorCriticConfig;
    use crate::batch_env::{BatchEnvironment, InProcess};

    /// Fills a rollout of `steps` steps on the small maze with fixed
    /// actions, rewards and episode ends drawn from `seed`.
    fn fill(
        path: GradPath,
        net: &ActorCritic,
        layout: &Layout,
        steps: usize,
        seed: u64,
    ) -> Rollout {
        let mut rollout = Rollout::new(path, 5, layout.width, layout.height, 1);
        refill(&mut rollout, net, layout, steps, seed);
        rollout
    }

    /// [`fill`] into an existing rollout of 5 environments.
    fn refill(rollout: &mut Rollout, net: &ActorCritic, layout: &Layout, steps: usize, seed: u64) {
        let n = 5;
        let cfg = EnvConfig::for_task(Task::MultiGoal, layout);
        let mut env = InProcess::new(layout.clone(), cfg, n, seed, 1).expect("env");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut state = net.zero_state(n as i64);
        rollout.start(&state);
        let goals: Vec<u32> = (0..n as u32).map(|i| 14 + 3 * i).collect();
        for _ in 0..steps {
            let out = rollout.act(net, &env.observe(), Some(GoalMarks::one(&goals)), &state);
            let actions: Vec<u8> = (0..n).map(|_| rng.random_range(0..3)).collect();
            env.step(&actions).expect("step");
            let rewards: Vec<f32> = (0..n).map(|_| rng.random_range(-0.1..1.0)).collect();
            let dones: Vec<bool> = (0..n).map(|_| rng.random_bool(0.15)).collect();
            let weights: Vec<f32> = (0..n)
                .map(|_| f32::from(u8::from(rng.random_bool(0.9))))
                .collect();
            rollout.record(&actions, &rewards, &dones, &weights);
            state = out.state.reset_done(&mask(&dones));
        }
        rollout.bootstrap =
            bootstrap_values(net, &env.observe(), Some(GoalMarks::one(&goals)), &state);
    }

    #[test]
    fn the_batched_recomputation_gives_the_per_step_loss_and_gradients() {
        let layout = Maze::Small.layout(false);
        let vs = nn::VarStore::new(tch::Device::Cpu);
        let net = crate::seeding::init_seeded(4, || {
            ActorCritic::new(
                &vs.root(),
                &ActorCriticConfig {
                    conv_channels: [8, 16],
                    hidden: 32,
                    num_actions: 3,
                    goal_planes: 1,
                },
                layout.width,
                layout.height,
            )
        });
        let grads = |path| {
            let rollout = fill(path, &net, &layout, 12, 9);
            loss_and_gradients(&rollout, &net, &vs)
        };
        let (loss_fast, fig_fast, g_fast) = grads(GradPath::Recompute);
        let (loss_plain, fig_plain, g_plain) = grads(GradPath::Plain);
        let (loss_step, _, g_step) = grads(GradPath::PerStep);
        assert!(
            (loss_step - loss_plain).abs() < 1e-5,
            "{loss_step} vs {loss_plain}"
        );
        for ((name, a), (_, b)) in g_step.iter().zip(&g_plain) {
            let scale = b.abs().max().double_value(&[]).max(1e-3);
            assert!(
                (a - b).abs().max().double_value(&[]) / scale < 1e-4,
                "{name} (per-step, gather)"
            );
        }
        assert!(
            (loss_fast - loss_plain).abs() < 1e-5,
            "{loss_fast} vs {loss_plain}"
        );
        assert!((fig_fast.entropy - fig_plain.entropy).abs() < 1e-5);
        assert_eq!(fig_fast.entries, fig_plain.entries);
        assert!(
            fig_fast.entries < 60.0,
            "some steps are left out by weight 0"
        );
        for ((name, a), (_, b)) in g_fast.iter().zip(&g_plain) {
            let scale = b.abs().max().double_value(&[]).max(1e-3);
            let diff = (a - b).abs().max().double_value(&[]);
            assert!(
                diff / scale < 1e-4,
                "{name}: gradients differ by {diff} (scale {scale})"
            );
            assert!(
                b.abs().sum(tch::Kind::Float).double_value(&[]) > 0.0,
                "{name} has no gradient"
            );
        }
    }

    /// The loss and every parameter's gradient of `rollout` (the gradients
    /// zeroed first), by parameter name.
    fn loss_and_gradients(
        rollout: &Rollout,
        net: &ActorCritic,
        vs: &nn::VarStore,
    ) -> (f64, LossFigures, Vec<(String, Tensor)>) {
        for v in vs.trainable_variables() {
            if v.grad().defined() {
                let _ = v.grad().zero_();
            }
        }
        let (loss, figures) = rollout.loss(net, &A2cConfig::default());
        loss.backward();
        let mut named: Vec<(String, Tensor)> = vs
            .variables()
            .into_iter()
            .map(|(k, v)| (k, v.grad().copy()))
            .collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        (loss.double_value(&[]), figures, named)
    }

    /// Asserts that two paths' losses differ by less than 1e-5 (absolute)
    /// and each parameter's gradients by less than 1e-5 of that gradient's
    /// largest magnitude (relative), and that every gradient is non-zero.
    fn assert_same_function(
        what: &str,
        (loss_a, fig_a, grads_a): &(f64, LossFigures, Vec<(String, Tensor)>),
        (loss_b, fig_b, grads_b): &(f64, LossFigures, Vec<(String, Tensor)>),
    ) {
        assert!(
            (loss_a - loss_b).abs() < 1e-5,
            "{what}: losses {loss_a} and {loss_b}"
        );
        assert!((fig_a.entropy - fig_b.entropy).abs() < 1e-5, "{what}");
        assert_eq!(fig_a.entries, fig_b.entries, "{what}");
        assert_eq!(grads_a.len(), grads_b.len());
        for ((name, a), (name_b, b)) in grads_a.iter().zip(grads_b) {
            assert_eq!(name, name_b);
            let scale = b.abs().max().double_value(&[]);
            let diff = (a - b).abs().max().double_value(&[]);
            assert!(scale > 0.0, "{what}: {name} has no gradient");
            assert!(
                diff / scale < 1e-5,
                "{what}: {name}'s gradients differ by {diff:e} (largest {scale:e}, relative {:e})",
                diff / scale
            );
        }
    }

    /// A network of the agents' default sizes (conv 16/32, LSTM 128).
    fn default_net(vs: &nn::VarStore, goal_planes: usize, w: usize, h: usize) -> ActorCritic {
        crate::seeding::init_seeded(11, || {
            ActorCritic::new(
                &vs.root(),
                &ActorCriticConfig {
                    goal_planes,
                    ..ActorCriticConfig::default()
                },
                w,
                h,
            )
        })
    }

    #[test]
    fn the_own_kernels_give_the_per_step_loss_and_gradients_on_a_simulator_rollout() {
        for maze in [Maze::Small, Maze::Medium] {
            let layout = maze.layout(false);
            let vs = nn::VarStore::new(tch::Device::Cpu);
            let net = default_net(&vs, 1, layout.width, layout.height);
            let run = |path| loss_and_gradients(&fill(path, &net, &layout, 20, 9), &net, &vs);
            let per_step = run(GradPath::PerStep);
            assert!(
                per_step.1.entries < 100.0,
                "some steps are left out by weight 0"
            );
            for path in [GradPath::RustEncoder, GradPath::RustCore] {
                let what = format!("{maze:?}, {}", path.name());
                assert_same_function(&what, &run(path), &per_step);
            }
        }
    }

    #[test]
    fn the_own_kernels_give_the_per_step_loss_and_gradients_on_random_inputs() {
        // Random grids (any cell code), agents anywhere facing anywhere,
        // keys carried or not, two goal slots (one sometimes empty or on
        // the agent's cell), random rewards and episode ends.
        let (w, h, n, steps) = (11, 8, 6, 15);
        let vs = nn::VarStore::new(tch::Device::Cpu);
        let net = default_net(&vs, 2, w, h);
        let run = |path| {
            let mut rng = SmallRng::seed_from_u64(21);
            let mut rollout = Rollout::new(path, n, w, h, 2);
            let mut state = net.zero_state(n as i64);
            rollout.start(&state);
            let draw = |rng: &mut SmallRng| {
                let (cells, meta) = crate::a2c::input::random_obs(rng, n, w, h, 0.3);
                let goals: Vec<u32> = (0..2 * n)
                    .map(|k| match rng.random_range(0..4) {
                        0 => crate::a2c::input::NO_GOAL,
                        1 => u32::from(meta[k / 2].y) * w as u32 + u32::from(meta[k / 2].x),
                        _ => rng.random_range(0..(w * h) as u32),
                    })
                    .collect();
                (cells, meta, goals)
            };
            for _ in 0..steps {
                let (cells, meta, goals) = draw(&mut rng);
                let obs = crate::a2c::input::test_view(&cells, &meta, w, h);
                let marks = GoalMarks {
                    cells: &goals,
                    per_env: 2,
                };
                let out = rollout.act(&net, &obs, Some(marks), &state);
                let actions: Vec<u8> = (0..n).map(|_| rng.random_range(0..3)).collect();
                let rewards: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
                let dones: Vec<bool> = (0..n).map(|_| rng.random_bool(0.2)).collect();
                rollout.record(&actions, &rewards, &dones, &vec![1.0; n]);
                state = out.state.reset_done(&mask(&dones));
            }
            rollout.bootstrap = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            loss_and_gradients(&rollout, &net, &vs)
        };
        let per_step = run(GradPath::PerStep);
        for path in [GradPath::RustEncoder, GradPath::RustCore] {
            let what = format!("random inputs, {}", path.name());
            assert_same_function(&what, &run(path), &per_step);
        }
    }

    #[test]
    fn the_own_kernels_read_the_weights_anew_each_rollout() {
        // Two rollouts into one `Rollout` with an optimiser step between
        // them: the second's gradients are those of the updated weights.
        let layout = Maze::Small.layout(false);
        let results: Vec<_> = [GradPath::PerStep, GradPath::RustEncoder, GradPath::RustCore]
            .into_iter()
            .map(|path| {
                let vs = nn::VarStore::new(tch::Device::Cpu);
                let net = default_net(&vs, 1, layout.width, layout.height);
                let mut opt = crate::a2c::optim::Adam::new(&[("net", &vs)], 1e-2);
                let mut rollout = fill(path, &net, &layout, 6, 3);
                let (loss, _) = rollout.loss(&net, &A2cConfig::default());
                opt.backward_step(&loss, 0.5);
                refill(&mut rollout, &net, &layout, 6, 4);
                loss_and_gradients(&rollout, &net, &vs)
            })
            .collect();
        assert_same_function("after an update, rust-encoder", &results[1], &results[0]);
        assert_same_function("after an update, rust-core", &results[2], &results[0]);
    }
}
