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
//! - [`GradPath::PerStep`] (the default): each step runs the network with
//!   autograd (first layer by gather-and-sum) and keeps its logits and
//!   value; the update back-propagates through those graphs;
//! - [`GradPath::Plain`]: the same with the dense first convolution over
//!   one-hot planes (the benchmark's baseline).
//!
//! All three give the same loss and gradients for the same rollout (a test
//! checks it). Which is fastest is measured by `worldgraph bench learner`:
//! with these small networks on a CPU the update is compute-bound, so the
//! recomputation's second forward pass costs more than batching saves.

use tch::{Kind, Tensor, nn};

pub use super::grad_path::GradPath;
use super::input::{CellInput, GoalMarks, encode_obs, goal_planes};
use super::net::{ActorCritic, ActorCriticOutput, LstmState};
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
            GradPath::PerStep | GradPath::Plain => (
                Tensor::cat(&self.graph_logits, 0),
                Tensor::cat(&self.graph_values, 0),
            ),
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
        a2c_loss(&terms, &adv, &ret, &self.weights, cfg)
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

/// The values of a float tensor.
pub fn floats(t: &Tensor) -> Vec<f32> {
    Vec::<f32>::try_from(&t.to_kind(Kind::Float).contiguous().flatten(0, -1))
        .expect("invariant: a float tensor converts to Vec<f32>")
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
        let n = 5;
        let cfg = EnvConfig::for_task(Task::MultiGoal, layout);
        let mut env = InProcess::new(layout.clone(), cfg, n, seed, 1).expect("env");
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut rollout = Rollout::new(path, n, layout.width, layout.height, 1);
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
        rollout
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
        let cfg = A2cConfig::default();
        let grads = |path| {
            let rollout = fill(path, &net, &layout, 12, 9);
            for v in vs.trainable_variables() {
                if v.grad().defined() {
                    let _ = v.grad().zero_();
                }
            }
            let (loss, figures) = rollout.loss(&net, &cfg);
            loss.backward();
            let mut named: Vec<(String, Tensor)> = vs
                .variables()
                .into_iter()
                .map(|(k, v)| (k, v.grad().copy()))
                .collect();
            named.sort_by(|a, b| a.0.cmp(&b.0));
            (loss.double_value(&[]), figures, named)
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
}
