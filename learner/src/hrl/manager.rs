//! The Manager's side of an agent (Shang et al. 2019, sections 4.1–4.2):
//! its network ([`Manager`], with the Feudal head of section 4.1 or the
//! Wide-then-Narrow head of section 4.2), var store and optimiser, the
//! wide-goal candidates `V` and the narrow window, and its decisions.
//!
//! A decision is taken for every environment whose interval ended (or
//! whose episode started; [`ManagerSide::decide`]): the Manager's core
//! steps once on the observation, and it picks a goal ([`Pick`]) — FN a
//! subgoal cell from its softmax over the valid cells; WN a wide goal
//! `g_w ∈ V` from `π^ω`, then a narrow goal `g_n` in the window around
//! `g_w` from `π^n`. The Worker starts a fresh goal episode towards it.
//! While training, each decision joins its environment's queue, and the
//! Manager learns from the queues after each rollout
//! ([`ManagerSide::update`]).

use planner::WorldGraph;
use sim::{Layout, ReplayRng};
use tch::{Tensor, nn};

use super::config::{AgentConfig, AgentKind};
use super::controller::Controller;
use super::feudal::{Decision, GoalBias, Manager, ManagerHead, OwnTrunk};
use super::manager_kernels::{OwnDecision, OwnManager};
use super::reports::{Decisions, Tracing};
use super::wide_narrow::{self, WideNarrowHead, Window};
use super::worker::WorkerGoal;
use crate::a2c::input::{BASE_CHANNELS, CellInput, mask};
use crate::a2c::net::{LstmState, Trunk};
use crate::a2c::optim::Adam;
use crate::a2c::rollout::GradPath;
use crate::a2c::tensors::floats;
use crate::a2c::{A2cConfig, LossFigures, PhaseTimes};
use crate::batch_env::ObsView;

/// One Manager choice for one environment.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Pick {
    /// As trained: FN the subgoal cell, WN the index of `g_w` in `V`.
    pub(super) wide: i64,
    /// As trained: WN the window slot of `g_n` (FN: 0).
    pub(super) narrow: i64,
    /// The wide goal `g_w` (FN: the subgoal).
    pub(super) wide_cell: u32,
    /// The narrow goal `g_n` (FN: the subgoal).
    pub(super) narrow_cell: u32,
    /// WN: the local input `s_w(g_w)` of the window.
    pub(super) local: Vec<f32>,
    /// WN: the window's valid narrow slots.
    pub(super) valid: Vec<bool>,
}

/// The Manager's side of an agent (module docs).
#[derive(Debug)]
pub(super) struct ManagerSide {
    width: usize,
    height: usize,
    pub(super) vs: nn::VarStore,
    pub(super) net: Manager,
    pub(super) opt: Adam,
    /// Wide-goal cells `V` (WN; empty for FN).
    pub(super) candidates: Vec<u32>,
    /// The narrow window (WN).
    pub(super) window: Option<Window>,
    /// [`AgentConfig::object_goals`]: a wide goal on an object is its own
    /// narrow goal.
    object_goals: bool,
    /// Where the decisions run: [`GradPath::RustCore`] in the own kernels
    /// ([`OwnManager`]), any other path in tch.
    path: GradPath,
    /// The own kernels' copy of the network, built at the first decision
    /// and read again after every update (`None`: not built, or stale).
    own: std::sync::Mutex<Option<OwnManager>>,
}

/// Where a batch of decisions draws its goals from: the tch network's
/// outputs or the own kernels'.
enum Chooser<'a> {
    Tch {
        head: &'a ManagerHead,
        h: Tensor,
        bias: Option<GoalBias>,
    },
    Own {
        own: &'a OwnManager,
        decision: OwnDecision,
    },
}

impl Chooser<'_> {
    /// FN: the subgoal probabilities `[n, H·W]`.
    fn feudal(&self, net: &Manager) -> Vec<f32> {
        match self {
            Chooser::Tch { h, bias, .. } => floats(
                &net.feudal_policy(h, bias.as_ref().map(|b| &b.wide))
                    .expect("feudal")
                    .probs(),
            ),
            Chooser::Own { own, decision } => own.feudal_probs(decision),
        }
    }

    /// WN: `π^ω`'s probabilities `[n, |V|]`.
    fn wide(&self) -> Vec<f32> {
        match self {
            Chooser::Tch { head, h, bias } => floats(
                &wn_head(head)
                    .wide(h, bias.as_ref().map(|b| &b.wide))
                    .probs(),
            ),
            Chooser::Own { own, decision } => own.wide_probs(decision),
        }
    }

    /// WN: `π^n`'s probabilities `[n, N·N]` around the wide goals `wide`
    /// (indices in `V`), from the local inputs and valid slots.
    fn narrow(&self, wide: &[usize], local: &[f32], valid: &[bool]) -> Vec<f32> {
        match self {
            Chooser::Tch { head, h, bias } => {
                let n = wide.len() as i64;
                let wide_idx =
                    Tensor::from_slice(&wide.iter().map(|&k| k as i64).collect::<Vec<_>>());
                tch::no_grad(|| {
                    let map = bias
                        .as_ref()
                        .and_then(|b| b.windows.as_ref())
                        .map(|w| WideNarrowHead::narrow_bias(w, &wide_idx));
                    floats(
                        &wn_head(head)
                            .narrow(
                                h,
                                &wide_idx,
                                &Tensor::from_slice(local).view([n, -1]),
                                &Tensor::from_slice(valid).view([n, -1]),
                                map.as_ref(),
                            )
                            .probs(),
                    )
                })
            }
            Chooser::Own { own, decision } => own.narrow_probs(decision, wide, local, valid),
        }
    }
}

fn wn_head(head: &ManagerHead) -> &WideNarrowHead {
    match head {
        ManagerHead::WideNarrow(h) => h,
        ManagerHead::Feudal { .. } => panic!("a Feudal Manager has no Wide-then-Narrow head"),
    }
}

impl ManagerSide {
    /// A fresh Manager of `cfg` (FN or WN) on `layout`, WN's candidates
    /// over `V_all` or the nodes of `graph` (its weights are drawn from
    /// libtorch's generator: build it under
    /// [`crate::seeding::init_seeded`]).
    pub(super) fn new(
        cfg: &AgentConfig,
        layout: &Layout,
        graph: Option<&WorldGraph>,
    ) -> ManagerSide {
        let (width, height) = (layout.width, layout.height);
        let candidates = wide_narrow::wide_goal_candidates(cfg, layout, graph);
        let window = (cfg.kind == AgentKind::WideNarrow).then(|| {
            let side = match cfg.window {
                0 => wide_narrow::covering_side(cfg.window_side(width), &candidates, layout),
                n => n,
            };
            Window::new(side, layout)
        });
        let vs = nn::VarStore::new(tch::Device::Cpu);
        let trunk = Trunk::new(
            &vs.root(),
            BASE_CHANNELS as i64,
            cfg.conv_channels,
            cfg.hidden,
            width,
            height,
        );
        let net = Manager::new(&vs.root(), trunk, |p, hidden| match cfg.kind {
            AgentKind::WideNarrow => ManagerHead::WideNarrow(WideNarrowHead::new(
                p,
                hidden,
                candidates.len(),
                window.as_ref().map_or(1, Window::len),
            )),
            _ => Manager::feudal_head(p, hidden, &valid_cells(layout)),
        });
        let net = if cfg.goal_map {
            let cells = (cfg.kind == AgentKind::WideNarrow).then_some(&candidates[..]);
            let windows = window.as_ref().filter(|_| cfg.goal_map_windows);
            net.with_goal_map(
                &vs.root(),
                (cfg.conv_channels[0] / 2).max(1),
                cells,
                windows,
            )
        } else {
            net
        };
        let opt = Adam::new(&[("manager", &vs)], cfg.manager.learning_rate);
        ManagerSide {
            width,
            height,
            vs,
            net,
            opt,
            candidates,
            window,
            object_goals: cfg.object_goals,
            path: cfg.grad_path,
            own: std::sync::Mutex::new(None),
        }
    }

    /// The Manager decides for every environment of `ctl` that needs a new
    /// goal, on `obs`: its core steps, it picks the goals, and the Worker
    /// starts a fresh goal episode towards them. With `record`, the
    /// decisions join the training queues; with `greedy`, each goal is
    /// the policy's most likely ([`super::config::EvalActions`]); `trace`
    /// records the traced environment's.
    pub(super) fn decide(
        &self,
        ctl: &mut Controller,
        obs: &ObsView<'_>,
        record: bool,
        greedy: bool,
        mut trace: Option<&mut Tracing<'_>>,
    ) -> Decisions {
        let mut made = Decisions::default();
        let who: Vec<usize> = (0..ctl.envs.len())
            .filter(|&e| ctl.envs[e].need_decision)
            .collect();
        if who.is_empty() {
            return made;
        }
        let idx = Tensor::from_slice(&who.iter().map(|&e| e as i64).collect::<Vec<_>>());
        let mut input = CellInput::new(self.width, self.height, 0);
        for &e in &who {
            input.push_env(obs, e, None);
        }
        let resets: Vec<bool> = who.iter().map(|&e| ctl.envs[e].manager_reset).collect();
        let mut own_net = self.own.lock().expect("invariant: no panic while deciding");
        let (values, chooser) = if self.path == GradPath::RustCore {
            let own =
                own_net.get_or_insert_with(|| OwnManager::new(&self.net, self.width, self.height));
            let state = &mut ctl.manager_state;
            let decision = own_step(own, &input, state, &who, &resets);
            (decision.values.clone(), Chooser::Own { own, decision })
        } else {
            let state = ctl.manager_state.select(&idx).reset_done(&mask(&resets));
            let step = self.net.act(&input, &state);
            let bias = tch::no_grad(|| self.net.goal_bias(&input));
            ctl.manager_state.scatter(&idx, &step.state);
            let chooser = Chooser::Tch {
                head: self.net.head(),
                h: step.h,
                bias,
            };
            (step.values, chooser)
        };
        let picks = match self.net.head() {
            ManagerHead::Feudal { .. } => self.pick_feudal(&chooser, &mut ctl.rng, greedy),
            ManagerHead::WideNarrow(_) => {
                self.pick_wide_narrow(&chooser, obs, &who, &mut ctl.rng, greedy)
            }
        };
        drop(chooser);
        drop(own_net);
        for (j, (&e, pick)) in who.iter().zip(picks).enumerate() {
            let c = &mut ctl.envs[e];
            if record {
                let mut one = CellInput::new(self.width, self.height, 0);
                one.push_env(obs, e, None);
                ctl.queues[e].decisions.push(Decision {
                    input: one,
                    wide: pick.wide,
                    narrow: pick.narrow,
                    local: pick.local,
                    valid: pick.valid,
                    value: values[j],
                    reset_before: c.manager_reset,
                    rewards: Vec::new(),
                    complete: false,
                    episode_ended: false,
                    final_value: None,
                });
            }
            if let Some(t) = trace.as_deref_mut() {
                t.decision(e, pick.wide_cell, pick.narrow_cell);
            }
            let (gw, gn) = (pick.wide_cell, pick.narrow_cell);
            c.need_decision = false;
            c.manager_reset = false;
            c.goal = WorkerGoal::new(gw, gn, obs.meta[e].cell(self.width) as u32);
            made.count += 1;
            let grid = obs.env_cells(e);
            let named = grid.get(gn as usize).copied();
            made.exit_goals += usize::from(named == Some(sim::Object::Exit as u8));
            made.ball_goals += usize::from(named == Some(sim::Object::Ball as u8));
            // Door-Key: either goal on the key, or on a door not yet open.
            let on = |o: sim::Object| {
                [gw, gn]
                    .iter()
                    .any(|&g| grid.get(g as usize) == Some(&(o as u8)))
            };
            made.key_goals += usize::from(on(sim::Object::Key));
            made.door_goals +=
                usize::from(on(sim::Object::DoorLocked) || on(sim::Object::DoorClosed));
        }
        // A fresh goal episode for the Worker.
        let fresh: Vec<bool> = (0..ctl.envs.len()).map(|e| who.contains(&e)).collect();
        ctl.worker_state = ctl.worker_state.reset_done(&mask(&fresh));
        made
    }

    /// FN: a subgoal cell per decision of `chooser` (section 4.1), drawn
    /// from the softmax over the valid cells (plus the goal map's logits).
    fn pick_feudal(&self, chooser: &Chooser<'_>, rng: &mut ReplayRng, greedy: bool) -> Vec<Pick> {
        let width = self.width * self.height;
        crate::seeding::choose_rows(rng, &chooser.feudal(&self.net), width, greedy)
            .into_iter()
            .map(|cell| Pick {
                wide: cell as i64,
                narrow: 0,
                wide_cell: cell as u32,
                narrow_cell: cell as u32,
                local: Vec::new(),
                valid: Vec::new(),
            })
            .collect()
    }

    /// WN: for the environments `who` of `obs` (decisions of `chooser`), a
    /// wide goal `g_w` from `π^ω`, then a narrow goal `g_n` from `π^n`
    /// among the valid cells of the window around it (section 4.2), each
    /// plus the goal map's logits where it reaches them. The agent's own
    /// cell is no narrow goal (reaching means arriving), unless the window
    /// holds nothing else.
    fn pick_wide_narrow(
        &self,
        chooser: &Chooser<'_>,
        obs: &ObsView<'_>,
        who: &[usize],
        rng: &mut ReplayRng,
        greedy: bool,
    ) -> Vec<Pick> {
        let window = self.window.as_ref().expect("WN has a window");
        let wide = crate::seeding::choose_rows(rng, &chooser.wide(), self.candidates.len(), greedy);
        let mut locals = Vec::new();
        let mut valids = Vec::new();
        for (j, &e) in who.iter().enumerate() {
            let gw = self.candidates[wide[j]];
            locals.push(window.local_input(obs, e, gw));
            let mut valid = window.valid(gw);
            let here = obs.meta[e].cell(self.width) as u32;
            let object = obs
                .env_cells(e)
                .get(gw as usize)
                .and_then(|&c| sim::Object::from_code(c))
                .is_some_and(sim::Object::is_acted_on);
            if self.object_goals && object {
                // An object goal (the key, a closed door) is exact already:
                // the narrow goal is the object itself, so the interval
                // ends when the Worker acts on it.
                let centre = window.slot_of(gw, gw).expect("the centre is in its window");
                valid
                    .iter_mut()
                    .enumerate()
                    .for_each(|(k, v)| *v = k == centre);
            } else if let Some(k) = window.slot_of(gw, here)
                && valid.iter().filter(|&&v| v).count() > 1
            {
                valid[k] = false;
            }
            valids.push(valid);
        }
        let narrow = crate::seeding::choose_rows(
            rng,
            &chooser.narrow(&wide, &locals.concat(), &valids.concat()),
            window.len(),
            greedy,
        );
        (0..who.len())
            .map(|j| {
                let gw = self.candidates[wide[j]];
                Pick {
                    wide: wide[j] as i64,
                    narrow: narrow[j] as i64,
                    wide_cell: gw,
                    narrow_cell: window
                        .cell(gw, narrow[j])
                        .expect("a valid slot is inside the grid"),
                    local: std::mem::take(&mut locals[j]),
                    valid: std::mem::take(&mut valids[j]),
                }
            })
            .collect()
    }

    /// Bootstraps the intervals of environments `cut`, which the episode's
    /// step limit cut, from the Manager's values of their final states.
    pub(super) fn bootstrap_cut(&self, ctl: &mut Controller, obs: &ObsView<'_>, cut: &[usize]) {
        let state = &ctl.manager_state;
        for (&e, v) in cut.iter().zip(self.net.final_values(obs, state, cut)) {
            if let Some(q) = ctl.queues[e].decisions.last_mut() {
                q.final_value = Some(v);
            }
        }
    }

    /// The Manager's A2C update on the decision queues of `ctl` (`cfg`: its
    /// settings), after which each queue keeps only its interval under way;
    /// the time it took goes to `times`.
    pub(super) fn update(
        &mut self,
        ctl: &mut Controller,
        cfg: &A2cConfig,
        times: &mut PhaseTimes,
    ) -> LossFigures {
        let t0 = std::time::Instant::now();
        let init = ctl.manager_init.take().expect("Manager init state");
        let own_path = self.path == GradPath::RustCore;
        let own = self.own.get_mut().expect("invariant: not poisoned");
        let l = self.net.loss_with(
            &ctl.queues,
            &init,
            cfg,
            cfg.gamma,
            own.as_mut()
                .filter(|_| own_path)
                .map(|o| o as &mut dyn OwnTrunk),
        );
        let t1 = PhaseTimes::lap(&mut times.loss, t0);
        if l.figures.entries > 0.0 {
            self.opt.backward_step(&l.loss, cfg.grad_clip_norm);
            self.weights_changed();
        }
        PhaseTimes::lap(&mut times.backward, t1);
        ctl.manager_init = Some(l.next_init);
        for q in &mut ctl.queues {
            let last = q.decisions.pop();
            q.decisions.clear();
            q.decisions.extend(last);
        }
        l.figures
    }

    /// Runs the decisions on gradient path `path` (module docs of
    /// [`super::manager_kernels`]).
    pub(super) fn set_grad_path(&mut self, path: GradPath) {
        self.path = path;
        self.weights_changed();
    }

    /// The weights changed (an update, a checkpoint restored): the own
    /// kernels read them again at the next decision.
    pub(super) fn weights_changed(&mut self) {
        if let Some(own) = self
            .own
            .get_mut()
            .expect("invariant: not poisoned")
            .as_mut()
        {
            own.load(&self.net);
        }
    }

    /// Model FLOPs of one decision: the Manager's forward and backward.
    pub(super) fn flops_per_decision(&self) -> f64 {
        let (c1, rest) = crate::a2c::net::trunk_macs(self.net.trunk(), Some(10.0));
        2.0 * 3.0 * (c1 + rest)
    }
}

/// Which cells of `layout` can be an FN subgoal: every valid cell.
fn valid_cells(layout: &Layout) -> Vec<bool> {
    let mut v = vec![false; layout.width * layout.height];
    for c in planner::pivotal::v_all(layout) {
        v[c.index()] = true;
    }
    v
}

/// One step of the own kernels' core for the environments `who`: their
/// rows of `state` (zeroed where `resets`) in, the new rows written back.
fn own_step(
    own: &mut OwnManager,
    input: &CellInput,
    state: &mut LstmState,
    who: &[usize],
    resets: &[bool],
) -> OwnDecision {
    let (mut all_h, mut all_c) = (floats(&state.h), floats(&state.c));
    let rows = state.h.size()[0];
    let hd = all_h.len() / rows as usize;
    let (mut h, mut c) = (vec![0f32; who.len() * hd], vec![0f32; who.len() * hd]);
    for (j, (&e, &reset)) in who.iter().zip(resets).enumerate() {
        if !reset {
            h[j * hd..][..hd].copy_from_slice(&all_h[e * hd..][..hd]);
            c[j * hd..][..hd].copy_from_slice(&all_c[e * hd..][..hd]);
        }
    }
    let d = own.act(input, &h, &c);
    for (j, &e) in who.iter().enumerate() {
        all_h[e * hd..][..hd].copy_from_slice(&d.h[j * hd..][..hd]);
        all_c[e * hd..][..hd].copy_from_slice(&d.c[j * hd..][..hd]);
    }
    *state = LstmState {
        h: Tensor::from_slice(&all_h).view([rows, hd as i64]),
        c: Tensor::from_slice(&all_c).view([rows, hd as i64]),
    };
    d
}
