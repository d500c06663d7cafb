//! The Worker (Shang et al. 2019, sections 4.1–4.2): a goal-conditioned
//! A2C-LSTM with `π_g`'s architecture, "rewarded if reaching `g_w` or `g_n`
//! within the horizon `c`" — by the Manager, not by the task.
//!
//! Per Worker step ([`WorkerGoal::book`]): the step penalty, plus the goal
//! reward when the step *brings* the agent onto `g_n`, or onto `g_w` for
//! the first time in the interval (the Feudal Worker has one goal,
//! `g_w = g_n`). Arrival is judged on the cell the action led to — on the
//! step that ends the environment's episode too, whose observation already
//! shows the next episode's start ([`shm_schemas::EnvMeta::end_cell`]).
//! A goal on the cell the agent stands on when it is set is not paid until
//! the agent has left it and come back, so standing still (or turning)
//! earns nothing. Reaching `g_n` ends the Worker's goal episode and the
//! Manager's interval, and so do `c` Worker steps and the end of the
//! environment's episode; a goal episode cut short by the episode's step
//! limit (truncation) is bootstrapped from its final state
//! ([`WorkerStep::bootstrap`]). Handing over to a world-graph traversal
//! towards `g_w` also ends the goal episode, by default paid as reaching
//! `g_w` (the route brings the agent there;
//! [`HandOver`](super::config::HandOver)); the Worker resumes at `g_w` with
//! a fresh goal episode for `g_n`.
//!
//! The Worker sees its goals as marks on goal planes of its input
//! ([`goal_marks`]): the subgoal (FN), or `g_w` and `g_n` on planes of
//! their own (WN). Inside the agent, `WorkerSide` owns its A2C learner
//! ([`A2cLearner`]: network, optimiser, rollout), the kind the flat A2C
//! baseline ([`super::baseline`]) trains without goal planes.

use super::config::{AgentConfig, AgentKind, WorkerTaskEnd};
use crate::a2c::input::{GoalMarks, NO_GOAL};
use crate::a2c::learner::A2cLearner;
use crate::a2c::net::{ActorCriticOutput, LstmState};
use crate::batch_env::ObsView;

/// How the environment's episode stands after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EpisodeEnd {
    /// The episode goes on.
    Running,
    /// The task's own rule ended it (the exit, lava).
    Terminated,
    /// The step limit ended it.
    Truncated,
}

impl EpisodeEnd {
    /// The end a step record reports.
    pub fn of(meta: &shm_schemas::EnvMeta) -> EpisodeEnd {
        if meta.terminated() {
            EpisodeEnd::Terminated
        } else if meta.truncated() {
            EpisodeEnd::Truncated
        } else {
            EpisodeEnd::Running
        }
    }

    /// The episode ended (either way).
    pub fn ended(self) -> bool {
        self != EpisodeEnd::Running
    }
}

/// The Worker's goals in one environment's current interval.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WorkerGoal {
    /// The wide goal `g_w` (FN: the subgoal).
    pub wide: u32,
    /// The narrow goal `g_n` (FN: the subgoal).
    pub narrow: u32,
    /// `g_w` has been paid for in this interval.
    pub wide_paid: bool,
    /// Worker steps taken in this interval.
    pub steps: u32,
    /// The cell the agent left last step (arrival means moving onto a
    /// goal, not staying on it).
    pub last_cell: u32,
}

/// Where a Worker step led the agent, and whether it acted on an object
/// goal: changed the object lying on `g_w` or `g_n` (a key picked up, a
/// door opened), which reaches that goal ([`AgentConfig::object_goals`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Arrival {
    /// The cell the action led the agent to.
    pub cell: u32,
    /// The step changed the object on `g_w`.
    pub acted_on_wide: bool,
    /// The step changed the object on `g_n`.
    pub acted_on_narrow: bool,
}

impl Arrival {
    /// A step that acted on no object goal.
    pub fn walked(cell: u32) -> Arrival {
        Arrival {
            cell,
            acted_on_wide: false,
            acted_on_narrow: false,
        }
    }

    /// The arrival of a step that led to `cell`, with goals `(g_w, g_n)`
    /// holding the objects `before` the step and `after` it: a goal is
    /// acted on when an object the agent acts on ([`sim::Object::is_acted_on`])
    /// lay there and the step changed it.
    pub fn of_step(cell: u32, before: [(u32, u8); 2], after: [u8; 2]) -> Arrival {
        let acted = |k: usize| {
            before[k].1 != after[k]
                && sim::Object::from_code(before[k].1).is_some_and(sim::Object::is_acted_on)
        };
        Arrival {
            cell,
            acted_on_wide: acted(0),
            acted_on_narrow: acted(1),
        }
    }
}

/// What one Worker step earned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkerStep {
    /// The Worker's reward.
    pub reward: f32,
    /// The Worker's goal episode ended.
    pub done: bool,
    /// The interval is over (`g_n` reached, horizon, episode end).
    pub interval_over: bool,
    /// `g_n` was reached.
    pub reached: bool,
    /// The goal episode was cut by the environment's step limit, not ended
    /// by a goal, the horizon or the task: its target bootstraps from the
    /// final state's value.
    pub bootstrap: bool,
}

impl WorkerGoal {
    /// A fresh interval with goals `(wide, narrow)`, set while the agent
    /// stands on `here`.
    pub fn new(wide: u32, narrow: u32, here: u32) -> WorkerGoal {
        WorkerGoal {
            wide,
            narrow,
            // Standing on g_w already is not reaching it.
            wide_paid: wide == here,
            steps: 0,
            last_cell: here,
        }
    }

    /// Books one Worker step whose action led the agent to `cell` (on the
    /// step that ends the environment's episode: the finished episode's
    /// final cell), with the episode's state `end`, horizon `horizon`, goal
    /// reward `goal` and step penalty `penalty`; `task_end` says how a goal
    /// episode the task ended (not the Worker's goal) is booked.
    pub fn book(
        &mut self,
        cell: u32,
        end: EpisodeEnd,
        horizon: u32,
        goal: f32,
        penalty: f32,
        task_end: WorkerTaskEnd,
    ) -> WorkerStep {
        self.book_arrival(Arrival::walked(cell), end, horizon, goal, penalty, task_end)
    }

    /// [`WorkerGoal::book`] for a step that may also have acted on an
    /// object goal ([`Arrival`]): a goal on a key is reached when the step
    /// picks the key up, one on a closed or locked door when it opens it.
    pub fn book_arrival(
        &mut self,
        arrival: Arrival,
        end: EpisodeEnd,
        horizon: u32,
        goal: f32,
        penalty: f32,
        task_end: WorkerTaskEnd,
    ) -> WorkerStep {
        let cell = arrival.cell;
        self.steps += 1;
        let moved = cell != self.last_cell;
        self.last_cell = cell;
        let reached = (moved && cell == self.narrow) || arrival.acted_on_narrow;
        let wide_now = ((moved && cell == self.wide) || arrival.acted_on_wide) && !self.wide_paid;
        if wide_now {
            self.wide_paid = true;
        }
        let paid = reached || wide_now;
        let horizon_over = self.steps >= horizon;
        let over = reached || horizon_over || end.ended();
        WorkerStep {
            reward: penalty + if paid { goal } else { 0.0 },
            done: over,
            interval_over: over,
            reached,
            bootstrap: !reached
                && !horizon_over
                && match end {
                    EpisodeEnd::Truncated => true,
                    EpisodeEnd::Terminated => task_end == WorkerTaskEnd::Cut,
                    EpisodeEnd::Running => false,
                },
        }
    }

    /// Books `g_n` reached on `step` as `g_w` reached too: pays `pay` if
    /// `g_w` is another cell and was not paid before the step (`was_paid`)
    /// ([`super::config::AgentConfig::narrow_pays_wide`]). Every interval
    /// that reaches `g_n` then pays both goals, whichever way the Worker
    /// went, so a walk through `g_w` earns nothing over the shortest way.
    pub fn narrow_pays_wide(&mut self, step: &mut WorkerStep, was_paid: bool, pay: f32) {
        if step.reached && !was_paid && self.wide != self.narrow {
            step.reward += pay;
            self.wide_paid = true;
        }
    }

    /// Books a step the Worker did not take (a traversal's) that left the
    /// agent on `cell`.
    pub fn moved_to(&mut self, cell: u32) {
        self.last_cell = cell;
    }

    /// Books a hand-over to a traversal towards `g_w` on the step just
    /// booked as `step`: the goal episode ends, paid `pay` unless `g_w`
    /// was paid already (`goal` when it counts as reaching `g_w`).
    pub fn hand_over(&mut self, step: &mut WorkerStep, pay: f32) {
        if !self.wide_paid {
            step.reward += pay;
            self.wide_paid = true;
        }
        step.done = true;
    }
}

/// The Worker's goal marks of `goals`, [`AgentConfig::goal_planes`] per
/// environment: the subgoal (FN), or `g_w` and `g_n` on planes of their own
/// (WN), `g_w` only until it is paid (the Worker is rewarded for it once
/// per interval); none for the baseline.
pub fn goal_marks<'a>(kind: AgentKind, goals: impl Iterator<Item = &'a WorkerGoal>) -> Vec<u32> {
    match kind {
        AgentKind::WideNarrow => goals
            .flat_map(|g| [if g.wide_paid { NO_GOAL } else { g.wide }, g.narrow])
            .collect(),
        AgentKind::Feudal => goals.map(|g| g.narrow).collect(),
        AgentKind::A2c => Vec::new(),
    }
}

/// The Worker's side of an agent: its goal-conditioned A2C learner
/// (network, var store, optimiser, rollout) and how its goals mark its
/// input.
#[derive(Debug)]
pub(super) struct WorkerSide {
    kind: AgentKind,
    /// Goal planes of the input ([`AgentConfig::goal_planes`]).
    planes: usize,
    pub(super) learner: A2cLearner,
}

impl WorkerSide {
    /// A fresh Worker of `cfg` acting on a `width × height` grid with
    /// `num_actions` actions (its weights are drawn from libtorch's
    /// generator: build it under [`crate::seeding::init_seeded`]).
    pub(super) fn new(
        cfg: &AgentConfig,
        width: usize,
        height: usize,
        num_actions: usize,
    ) -> WorkerSide {
        WorkerSide {
            kind: cfg.kind,
            planes: cfg.goal_planes(),
            learner: A2cLearner::new(
                &cfg.network(num_actions),
                width,
                height,
                "worker",
                cfg.worker.learning_rate,
                cfg.grad_path,
                cfg.envs,
            ),
        }
    }

    /// The goal marks of `goals` ([`goal_marks`]).
    pub(super) fn goal_marks<'a>(&self, goals: impl Iterator<Item = &'a WorkerGoal>) -> Vec<u32> {
        goal_marks(self.kind, goals)
    }

    /// `cells` (of [`Self::goal_marks`]) as the goal planes of the input.
    pub(super) fn marks<'a>(&self, cells: &'a [u32]) -> Option<GoalMarks<'a>> {
        (self.planes > 0).then_some(GoalMarks {
            cells,
            per_env: self.planes,
        })
    }

    /// One step of the network on `obs` towards the goals `marks` (of
    /// [`Self::goal_marks`]) from `state`: recorded in the rollout when
    /// `train`, else without gradient.
    pub(super) fn act(
        &mut self,
        obs: &ObsView<'_>,
        marks: &[u32],
        state: &LstmState,
        train: bool,
    ) -> ActorCriticOutput {
        let goals = self.marks(marks);
        self.learner.act(obs, goals, state, train)
    }

    /// Adds `γ · V(s_final)` to the `rewards` of the environments `cut`,
    /// whose goal episodes the step limit cut (truncation is not
    /// termination), from their final states towards the goals `marks`.
    pub(super) fn bootstrap_truncated(
        &self,
        rewards: &mut [f32],
        obs: &ObsView<'_>,
        marks: &[u32],
        state: &LstmState,
        cut: &[usize],
        gamma: f64,
    ) {
        let goals = self.marks(marks);
        self.learner
            .bootstrap_truncated(rewards, obs, goals, state, cut, gamma);
    }

    /// The rollout's bootstrap values `V(s_T)` at `obs` towards `marks`.
    pub(super) fn bootstrap(&mut self, obs: &ObsView<'_>, marks: &[u32], state: &LstmState) {
        let goals = self.marks(marks);
        self.learner.bootstrap(obs, goals, state);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use EpisodeEnd::{Running, Terminated, Truncated};

    /// A goal on the key is reached by picking the key up (the object on
    /// the goal's cell changes), on a locked door by opening it; walking
    /// next to them, or a step that changes nothing, earns nothing.
    #[test]
    fn an_object_goal_is_reached_by_acting_on_it() {
        use sim::Object::{DoorLocked, DoorOpen, Floor, Key};
        let (goal, penalty, c, end) = (1.0, -0.01, 20, WorkerTaskEnd::Cut);
        let (key, door, beside) = (30, 40, 29);
        // g_w on the door, g_n on the key; the agent stands beside the key.
        let before = [(door, DoorLocked as u8), (key, Key as u8)];
        let mut g = WorkerGoal::new(door, key, beside);
        let idle = Arrival::of_step(beside, before, [DoorLocked as u8, Key as u8]);
        assert_eq!(idle, Arrival::walked(beside));
        let s = g.book_arrival(idle, Running, c, goal, penalty, end);
        assert_eq!(s.reward, penalty, "facing the key is not taking it");
        let picked = Arrival::of_step(beside, before, [DoorLocked as u8, Floor as u8]);
        assert!(picked.acted_on_narrow && !picked.acted_on_wide);
        let s = g.book_arrival(picked, Running, c, goal, penalty, end);
        assert_eq!(s.reward, penalty + goal, "picking the key up reaches g_n");
        assert!(s.reached && s.interval_over);
        // The door as g_w: opened, it is paid once.
        let mut g = WorkerGoal::new(door, key, beside);
        let opened = Arrival::of_step(beside, before, [DoorOpen as u8, Key as u8]);
        let s = g.book_arrival(opened, Running, c, goal, penalty, end);
        assert_eq!(s.reward, penalty + goal);
        assert!(g.wide_paid && !s.reached);
        let s = g.book_arrival(opened, Running, c, goal, penalty, end);
        assert_eq!(s.reward, penalty, "g_w is paid once per interval");
        // A cell that held no object the agent acts on is reached by walking.
        let floor = [(door, Floor as u8), (key, Floor as u8)];
        assert_eq!(
            Arrival::of_step(beside, floor, [Key as u8, Floor as u8]),
            Arrival::walked(beside)
        );
    }

    /// With `narrow_pays_wide`, an interval pays `g_w` and `g_n` whether
    /// the Worker walks through `g_w` or straight to `g_n`; off, only the
    /// walk through `g_w` earns both.
    #[test]
    fn reaching_g_n_pays_g_w_too_so_the_detour_through_g_w_earns_nothing() {
        let (goal, penalty, c, end) = (1.0, -0.01, 20, WorkerTaskEnd::Terminal);
        // g_w = 10, g_n = 12, set on cell 2; walks of (cells) under the
        // rule on or off: the interval's reward.
        let walk = |cells: &[u32], on: bool| -> f32 {
            let mut g = WorkerGoal::new(10, 12, 2);
            let mut total = 0.0;
            for &cell in cells {
                let was_paid = g.wide_paid;
                let mut s = g.book(cell, Running, c, goal, penalty, end);
                if on {
                    g.narrow_pays_wide(&mut s, was_paid, goal);
                }
                total += s.reward;
            }
            total
        };
        let (straight, through) = ([11, 12], [10, 11, 12]);
        assert_eq!(walk(&straight, false), 2.0 * penalty + goal);
        assert_eq!(walk(&through, false), 3.0 * penalty + 2.0 * goal);
        assert_eq!(walk(&straight, true), 2.0 * penalty + 2.0 * goal);
        assert_eq!(walk(&through, true), 3.0 * penalty + 2.0 * goal);
        assert!(walk(&straight, true) > walk(&through, true));
        // One goal (Feudal, or an object that is its own narrow goal) is
        // paid once.
        let mut g = WorkerGoal::new(7, 7, 2);
        let mut s = g.book(7, Running, c, goal, penalty, end);
        g.narrow_pays_wide(&mut s, false, goal);
        assert_eq!(s.reward, penalty + goal);
    }

    #[test]
    fn the_worker_is_paid_for_g_w_or_g_n_and_for_nothing_else() {
        let (goal, penalty, c) = (1.0, -0.01, 20);
        // Wide-then-Narrow: g_w = 10, g_n = 12, set on cell 2.
        let mut g = WorkerGoal::new(10, 12, 2);
        let s = g.book(3, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!((s.reward, s.done, s.interval_over), (penalty, false, false));
        let s = g.book(10, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal, "g_w is paid");
        assert!(!s.done, "reaching g_w does not end the interval");
        let s = g.book(11, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty);
        let s = g.book(10, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty, "g_w is paid once per interval");
        let s = g.book(12, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal, "g_n is paid");
        assert!(s.done && s.interval_over && s.reached && !s.bootstrap);
        // The horizon ends the interval unpaid.
        let mut g = WorkerGoal::new(10, 12, 2);
        let steps: Vec<WorkerStep> = (0..c)
            .map(|_| g.book(5, Running, c, goal, penalty, WorkerTaskEnd::Terminal))
            .collect();
        assert!(steps[..c as usize - 1].iter().all(|s| !s.done));
        assert!(steps[c as usize - 1].interval_over);
        assert!(steps.iter().all(|s| s.reward == penalty && !s.bootstrap));
        // Feudal: one goal, paid once.
        let mut g = WorkerGoal::new(7, 7, 2);
        let s = g.book(7, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal);
        // A hand-over pays g_w unless it was paid already.
        let mut g = WorkerGoal::new(10, 12, 2);
        let mut s = g.book(4, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        g.hand_over(&mut s, goal);
        assert_eq!(s.reward, penalty + goal);
        assert!(s.done);
        let mut s = g.book(10, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty, "g_w was paid at the hand-over");
        g.hand_over(&mut s, goal);
        assert_eq!(s.reward, penalty);
        // An unpaid hand-over (HandOver::Unpaid) ends the goal episode on
        // the step penalty alone.
        let mut g = WorkerGoal::new(10, 12, 2);
        let mut s = g.book(4, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        g.hand_over(&mut s, 0.0);
        assert_eq!(s.reward, penalty);
        assert!(s.done);
    }

    #[test]
    fn a_goal_reached_on_the_step_that_ends_the_episode_is_paid() {
        let (goal, penalty, c) = (1.0, -0.01, 20);
        // g_n is the exit (cell 12): the step onto it terminates the
        // episode, and the record's end cell is the exit.
        let mut g = WorkerGoal::new(10, 12, 11);
        let s = g.book(12, Terminated, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal, "arrival at the exit is paid");
        assert!(s.done && s.interval_over && s.reached);
        assert!(!s.bootstrap, "termination is not bootstrapped");
        // g_w reached on a truncated step: paid, and the cut goal episode
        // bootstraps.
        let mut g = WorkerGoal::new(10, 12, 9);
        let s = g.book(10, Truncated, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal);
        assert!(s.done && s.interval_over && !s.reached && s.bootstrap);
        // Missing on a terminated step (lava, or the exit when it is not
        // g_n) ends the interval unpaid; as a terminal, or as a cut that
        // bootstraps from the final state (WorkerTaskEnd::Cut).
        let mut g = WorkerGoal::new(10, 12, 9);
        let s = g.book(8, Terminated, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty);
        assert!(s.done && !s.bootstrap);
        let mut g = WorkerGoal::new(10, 12, 9);
        let s = g.book(8, Terminated, c, goal, penalty, WorkerTaskEnd::Cut);
        assert_eq!(s.reward, penalty);
        assert!(s.done && s.interval_over && s.bootstrap);
        // Reaching g_n on it is paid and ends the goal episode either way.
        let mut g = WorkerGoal::new(10, 12, 11);
        let s = g.book(12, Terminated, c, goal, penalty, WorkerTaskEnd::Cut);
        assert_eq!(s.reward, penalty + goal);
        assert!(s.done && s.reached && !s.bootstrap);
        // A truncation on the horizon's last step is the horizon's end.
        let mut g = WorkerGoal::new(10, 12, 9);
        let s = g.book(8, Truncated, 1, goal, penalty, WorkerTaskEnd::Terminal);
        assert!(s.done && !s.bootstrap);
    }

    #[test]
    fn a_goal_under_the_agent_is_paid_only_after_leaving_it() {
        let (goal, penalty, c) = (1.0, -0.01, 20);
        // g_n on the agent's own cell: a turn earns nothing.
        let mut g = WorkerGoal::new(30, 5, 5);
        let s = g.book(5, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty, "turning on the goal is not reaching it");
        assert!(!s.done);
        g.book(6, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        let s = g.book(5, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty + goal, "coming back is");
        assert!(s.reached);
        // g_w under the agent counts as reached already.
        let mut g = WorkerGoal::new(5, 9, 5);
        assert!(g.wide_paid);
        g.book(6, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        let s = g.book(5, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty, "g_w is not paid for the start");
        // A traversal's steps move the agent without booking.
        let mut g = WorkerGoal::new(30, 9, 5);
        g.moved_to(9);
        let s = g.book(9, Running, c, goal, penalty, WorkerTaskEnd::Terminal);
        assert_eq!(s.reward, penalty, "the Worker did not bring it there");
    }
}
