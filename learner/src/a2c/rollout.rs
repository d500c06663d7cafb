//! Rollout storage and the A2C update of an agent that acts at every
//! environment step (`π_g`, the A2C baseline, the Worker).
//!
//! A rollout holds `T` steps of `B` environments, entry `t·B + b`, plus the
//! core state it started from and the bootstrap values `V(s_T)` `[B]` (the
//! `+1` of CleanRL's `[T + 1, B]` layout). Two ways to fill it, chosen by
//! [`GradPath`] (the learner's configuration):
//!
//! - [`GradPath::RustCore`] (production): the whole network in the
//!   project's own kernels, no graph while acting; the loss in tch over the
//!   rollout's logits and values, the rest of the backward (through time)
//!   in the own kernels ([`crate::a2c::rust_net`]);
//! - [`GradPath::Tch`] (the reference): each step runs the network with
//!   tch's autograd (first layer by gather-and-sum) and keeps its logits and
//!   value; the update back-propagates through those graphs.
//!
//! Both give the same loss and gradients for the same rollout (tests check
//! it). With these small networks on a CPU the update is compute-bound, and
//! the own kernels' GEMM outruns libtorch's at these shapes
//! (`worldgraph bench learner`; the history in
//! `docs/notes/2026-12-01-learner-throughput.md`).

use tch::{Kind, Tensor, nn};

pub use super::grad_path::GradPath;
use super::input::{CellInput, GoalMarks, goal_planes};
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
    /// Logits and values of every step with their graphs (tch path).
    graph_logits: Vec<Tensor>,
    graph_values: Vec<Tensor>,
    /// The whole network in the own kernels and its activations (rust-core
    /// path; behind a lock because [`Self::loss`] runs its backward through
    /// `&self`).
    own_net: std::sync::Mutex<Option<RustActorCritic>>,
    /// Whether the own network's weights are to be re-read before the next
    /// step (set by [`Self::start`]: an update may have changed them).
    weights_stale: bool,
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
    /// An empty rollout of `num_envs` environments, filled on gradient path
    /// `path`.
    pub fn new(path: GradPath, num_envs: usize) -> Rollout {
        Rollout {
            path,
            num_envs,
            graph_logits: Vec::new(),
            graph_values: Vec::new(),
            own_net: std::sync::Mutex::new(None),
            weights_stale: true,
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
        self.graph_logits.clear();
        self.graph_values.clear();
        self.weights_stale = true;
        self.actions.clear();
        self.rewards.clear();
        self.dones.clear();
        self.values.clear();
        self.weights.clear();
        self.bootstrap.clear();
        self.init_state = Some(state.detach());
    }

    /// One step of `net` on `obs` from `state`, recorded for the update:
    /// in the own kernels (rust-core path), or with tch's autograd (tch
    /// path). The returned logits carry no graph in either case.
    pub fn act(
        &mut self,
        net: &ActorCritic,
        obs: &ObsView<'_>,
        goals: Option<GoalMarks<'_>>,
        state: &LstmState,
    ) -> ActorCriticOutput {
        let t0 = std::time::Instant::now();
        let mut input = CellInput::new(obs.width, obs.height, goal_planes(goals));
        input.push_obs(obs, goals);
        let t1 = PhaseTimes::lap(&mut self.times.encode, t0);
        match self.path {
            GradPath::RustCore => {
                let own = current(
                    &mut self.own_net,
                    std::mem::take(&mut self.weights_stale),
                    || RustActorCritic::new(net),
                    |own| own.load(net),
                );
                let out = own.step(&input, state);
                self.values.extend(floats(&out.value));
                PhaseTimes::lap(&mut self.times.act, t1);
                out
            }
            GradPath::Tch => {
                let out = net.step(&input, state);
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
            GradPath::Tch => (
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
        let mut rollout = Rollout::new(path, 5);
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
    fn the_own_kernels_give_the_tch_loss_and_gradients_on_a_simulator_rollout() {
        for maze in [Maze::Small, Maze::Medium, Maze::Large] {
            let layout = maze.layout(false);
            let vs = nn::VarStore::new(tch::Device::Cpu);
            let net = default_net(&vs, 1, layout.width, layout.height);
            let run = |path| loss_and_gradients(&fill(path, &net, &layout, 20, 9), &net, &vs);
            let reference = run(GradPath::Tch);
            assert!(
                reference.1.entries < 100.0,
                "some steps are left out by weight 0"
            );
            let what = format!("{maze:?}, rust-core");
            assert_same_function(&what, &run(GradPath::RustCore), &reference);
        }
    }

    #[test]
    fn the_own_kernels_give_the_tch_loss_and_gradients_on_random_inputs() {
        // Random grids (any cell code), agents anywhere facing anywhere,
        // keys carried or not, two goal slots (one sometimes empty or on
        // the agent's cell), random rewards and episode ends.
        let (w, h, n, steps) = (11, 8, 6, 15);
        let vs = nn::VarStore::new(tch::Device::Cpu);
        let net = default_net(&vs, 2, w, h);
        let run = |path| {
            let mut rng = SmallRng::seed_from_u64(21);
            let mut rollout = Rollout::new(path, n);
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
        assert_same_function(
            "random inputs, rust-core",
            &run(GradPath::RustCore),
            &run(GradPath::Tch),
        );
    }

    #[test]
    fn the_own_kernels_read_the_weights_anew_each_rollout() {
        // Two rollouts into one `Rollout` with an optimiser step between
        // them: the second's gradients are those of the updated weights.
        let layout = Maze::Small.layout(false);
        let results: Vec<_> = [GradPath::Tch, GradPath::RustCore]
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
        assert_same_function("after an update, rust-core", &results[1], &results[0]);
    }
}
