//! The settings of a stage 2 agent (Shang et al. 2019, section 4) and what
//! it takes from stage 1.
//!
//! - [`AgentConfig`]: which agent — the A2C baseline, the Feudal Network
//!   (section 4.1) or the Wide-then-Narrow Manager (section 4.2) over a
//!   candidate set `V` ([`Candidates`]) — with or without world graph
//!   traversal (section 4.3) and initialisation from `π_g` (section 4.4),
//!   and its sizes, horizon, window and rewards;
//! - [`HandOver`] and [`WorkerTaskEnd`]: how the Worker's reward books a
//!   hand-over to a traversal and a step on which the task ended the
//!   episode (see [`super::worker`]);
//! - [`WorldGraphInputs`]: the world graph and `π_g` of stage 1.

use planner::WorldGraph;
use serde::{Deserialize, Serialize};
use sim::{Layout, Task};

use crate::a2c::A2cConfig;
use crate::a2c::net::ActorCriticConfig;
use crate::a2c::rollout::GradPath;
use crate::error::{ConfigError, LearnerError};
use crate::gcp::GoalConditionedPolicy;

/// Which agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AgentKind {
    /// The A2C-LSTM baseline.
    A2c,
    /// The Feudal Network: Manager over every valid cell, Worker.
    #[serde(alias = "fn")]
    Feudal,
    /// Wide-then-Narrow Manager, Worker.
    #[serde(alias = "wn")]
    WideNarrow,
}

/// The candidate set `V` of wide goals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Candidates {
    /// `V_all`: every valid cell.
    All,
    /// `V_rand`: random cells, as many as `V_p`.
    Random,
    /// `V_p`: the pivotal states of a discovery run.
    Pivotal,
}

impl Candidates {
    /// The paper's symbol: `V_all`, `V_rand`, `V_p`.
    pub fn label(self) -> &'static str {
        match self {
            Candidates::All => "V_all",
            Candidates::Random => "V_rand",
            Candidates::Pivotal => "V_p",
        }
    }

    /// The name in configuration names and on the command line: `all`,
    /// `random`, `pivotal`.
    pub fn name(self) -> &'static str {
        match self {
            Candidates::All => "all",
            Candidates::Random => "random",
            Candidates::Pivotal => "pivotal",
        }
    }
}

/// What handing over to a world-graph traversal pays the Worker (section
/// 4.3 leaves it open: the traversal starts on "a pivotal state with a
/// route to `g_w`", wherever the Worker met it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HandOver {
    /// Paid as reaching `g_w`: the route brings the agent there, so
    /// reaching any node with a route to `g_w` is as good as reaching it.
    #[default]
    PaysWideGoal,
    /// Not paid: the Worker's goal episode ends on the step penalty alone,
    /// so the Worker is paid only for cells it walks onto itself.
    Unpaid,
}

/// Settings of a stage 2 agent. Sizes default to `π_g`'s (the paper
/// "inherit\[s\] most hyperparameters from the training of `π_g`"; the
/// Manager and the Worker "share similar model architecture").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AgentConfig {
    /// The agent.
    pub kind: AgentKind,
    /// Wide-goal candidates (WN).
    pub candidates: Candidates,
    /// World graph traversal (WN over `V_rand` or `V_p`).
    pub traversal: bool,
    /// Initialise the Manager's and the Worker's encoders (and the Worker's
    /// core and heads) from `π_g`.
    pub init_from_gcp: bool,
    /// Environments per update (the paper: 32 agents).
    pub envs: usize,
    /// Rollout length `T` per update.
    pub rollout_len: usize,
    /// Manager horizon `c` in Worker steps; 0: a third of the rollout (the
    /// paper's choice).
    pub horizon: usize,
    /// Side `N` of the narrow window; 0: auto, the paper's 5 on grids up to
    /// 25 cells wide and 7 beyond (5×5 small and medium, 7×7 large), widened
    /// to the smallest odd side whose windows around the wide-goal
    /// candidates cover every free cell
    /// ([`super::wide_narrow::covering_side`]). A non-zero side is used as
    /// given.
    pub window: usize,
    /// Output channels of the encoder's convolutions.
    pub conv_channels: [i64; 2],
    /// Width of the encoder output and the LSTM core.
    pub hidden: i64,
    /// The Worker's (and the baseline's) A2C.
    pub worker: A2cConfig,
    /// The Manager's A2C (`γ` per environment step; an interval of `k`
    /// steps is discounted by `γ^k`).
    pub manager: A2cConfig,
    /// The Worker's reward for reaching a goal.
    pub goal_reward: f32,
    /// The Worker's reward per step.
    pub step_penalty: f32,
    /// Fine-tune `π_g` on the traversal steps it steers (MultiGoal-
    /// Stochastic with traversal; [`super::steering`]).
    pub fine_tune_pi_g: bool,
    /// What a hand-over to a traversal pays the Worker.
    pub hand_over: HandOver,
    /// The Manager's goal map ([`super::feudal::GoalMap`]): a fully
    /// convolutional logit per cell added to its goal head's (FN, WN).
    pub goal_map: bool,
    /// WN: the goal map reaches `π^n` over the window of `g_w`, and `π^ω`
    /// through the log-sum-exp of the map over each candidate's window
    /// ([`super::feudal::GoalMap::with_windows`]); off, `π^ω` reads the map
    /// at the candidates' own cells only (the behaviour until `a1555f3`).
    pub goal_map_windows: bool,
    /// How the Worker books a step on which the task ended the episode
    /// before it reached `g_n` ([`WorkerTaskEnd`]).
    pub worker_task_end: WorkerTaskEnd,
    /// Door-Key: the task's objects are goals (the paper is silent). The
    /// key's and the locked door's cells join the wide-goal candidates
    /// `V` (and the world graph's nodes, so traversal can bring the agent
    /// in front of them), and a goal on such a cell is reached by acting
    /// on it — picking the key up, opening the door — not by stepping onto
    /// it ([`super::worker`]). Off: goals are cells to step onto and `V`
    /// holds standable cells only. Changes nothing on a layout without
    /// keys or closed doors. A wide goal on an object is its own narrow
    /// goal (the object is exact already: the interval ends when the
    /// Worker acts on it).
    pub object_goals: bool,
    /// Door-Key's action set ([`DoorKeyActions`]).
    pub door_key_actions: DoorKeyActions,
    /// The Worker's share `α` of the task's own rewards (the door, the
    /// exit, balls; not the step penalty), added to its goal rewards as
    /// FeUdal Networks' Worker is paid `r^I + α r` (Vezhnevets et al.
    /// 2017, eq. 6). 0: the paper's Worker, paid by the Manager alone.
    pub worker_task_share: f32,
    /// How the Worker's actions that `π_g` lacks (Door-Key's pick and open)
    /// start under `π_g` initialisation ([`ObjectActionInit`]).
    pub object_action_init: ObjectActionInit,
    /// Whether the exit's cell joins the wide-goal candidates `V` (and the
    /// world graph's nodes), as the task's objects do with `object_goals`
    /// ([`ExitCandidate`]).
    pub exit_candidate: ExitCandidate,
    /// How the first-layer weights of inputs `π_g` never saw start under
    /// `π_g` initialisation ([`UnseenInputs`]).
    pub unseen_inputs: UnseenInputs,
    /// How the Wide-then-Narrow Worker's `g_n` plane starts under `π_g`
    /// initialisation ([`NarrowPlaneInit`]).
    pub narrow_plane_init: NarrowPlaneInit,
    /// A count-based exploration bonus `β` (the paper uses none; MiniGrid's
    /// `PositionBonus` wrapper): while training, every step adds
    /// `β / √n` to the reward the agent learns its task from (the
    /// Manager's; the flat baseline's), `n` the visits of the agent's cell
    /// in its environment so far, counted across episodes. The bonus fades
    /// as the maze is covered, so the task's optimum is kept; it is never
    /// paid in validation or testing, and never to the Worker. 0: off.
    pub count_bonus: f32,
    /// Env steps (summed over the environments) over which the count-based
    /// bonus falls linearly from `β` to 0 (the paper uses none; count-based
    /// bonuses are commonly annealed so the last stretch of training
    /// optimises the task's reward alone). Past it the bonus is 0, so the
    /// agent then learns from the task's reward only. 0: the bonus fades by
    /// `1/√n` alone, never to 0.
    pub count_bonus_fade: u64,
    /// Potential-based shaping of the reward the agent learns its task
    /// from (the Manager's; the flat baseline's), after Ng, Harada &
    /// Russell (1999); the paper uses none. `Φ(s)` is `ball_shaping` × the
    /// balls collected so far in the episode, and every training step adds
    /// `γ Φ(s') − Φ(s)` (`γ` the learner's discount; `Φ(s') = 0` when the
    /// task ends the episode, while a cut episode keeps its `Φ`, as its
    /// value is bootstrapped). Shaping of this form leaves the task's
    /// optimal policies unchanged; on MultiGoal-Sparse 0.2, a ball's worth
    /// at the exit, pays each ball when it is collected and takes the
    /// payment back at the exit. Never paid in validation or testing, never
    /// to the Worker. 0: off.
    pub ball_shaping: f32,
    /// WN with traversal: a traversal starts only while the agent stands
    /// outside the narrow window around `g_w` (section 4.3 says the Worker
    /// *can* traverse when it meets a pivotal state with a route to `g_w`;
    /// it is silent on when it should not). Inside the window `g_n` is at
    /// most half the window's side away on each axis, and a route to `g_w`
    /// first can lead away from it and back: the Worker walks to `g_n`
    /// itself. Off: a traversal starts from any such pivotal state until
    /// `g_w` is reached (the paper's wording taken literally). Changes
    /// nothing without traversal.
    pub traverse_outside_window: bool,
    /// WN with traversal: a traversal ends as soon as it brings the agent
    /// into the narrow window around `g_w`, `g_w` counted as reached, and
    /// the Worker walks to `g_n` from there; no traversal starts inside the
    /// window (as with `traverse_outside_window`). Section 4.3 transports
    /// the agent to `g_w` itself; `g_n` lies anywhere in `g_w`'s window, so
    /// the walk on from `g_w` can lead back the way the traversal came.
    /// Off: the paper's, the traversal runs to `g_w`. A traversal to an
    /// object (Door-Key's key or door) always runs to the front of it.
    pub traversal_ends_in_window: bool,
    /// WN: reaching `g_n` pays `g_w` as well when `g_w` was not reached
    /// in the interval. Section 4.2 rewards the Worker "if reaching `g_w`
    /// or `g_n` within the horizon `c`"; read as one reward for each goal
    /// on arrival (off, the default), the Worker earns twice by walking
    /// through `g_w` on its way to `g_n` and learns that detour even where
    /// `g_n` is nearer. On, every interval that reaches `g_n` pays both
    /// goals, whichever way, so the shortest way to `g_n` is the Worker's
    /// best (`g_w` still pays on arrival, and a traversal's hand-over as
    /// [`HandOver`] says).
    pub narrow_pays_wide: bool,
    /// The Worker's reward for each ball it collects on its own steps (not
    /// a traversal's), on top of its goal rewards (the paper is silent; the
    /// Worker is paid by the Manager's goals alone). MultiGoal-Sparse pays
    /// the balls only at the exit, so a Worker walking one cell past a ball
    /// the Manager did not name has nothing to turn for. Paid in training
    /// only, never to the Manager. 0: off.
    pub worker_ball_reward: f32,
    /// How the agent acts when it is not training: in validation, in the
    /// test and in `evaluate` (section 5 is silent). Training always
    /// samples.
    pub eval_actions: EvalActions,
    /// How the Worker's (or the baseline's) and the Manager's updates get
    /// their gradients: `"rust-core"` (production, the default; not written
    /// to `config.toml`) or `"tch"` (the reference the tests hold it equal
    /// to). Both compute the same update; the figures differ in the last
    /// float bits.
    #[serde(skip_serializing_if = "GradPath::is_production")]
    pub grad_path: GradPath,
}

/// Whether the exit joins the wide-goal candidates `V` (section 4 is
/// silent: the paper's `V` holds pivotal states, or random or all cells).
/// Named as a candidate the exit is one Manager decision away through
/// traversal, and the exit ends every task.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ExitCandidate {
    /// On a layout with objects to act on (Door-Key) only. There the exit
    /// lies behind the locked door, and off, it is a narrow goal only,
    /// reachable from the windows of the candidates near it (on the small
    /// maze from one wide goal in about twenty, at a window's corner,
    /// where a Manager that had learned to open the door named it in
    /// 0.1 % of its decisions and never exited). On the MultiGoal tasks
    /// the exit's reward is at hand from the first decision, and a Manager
    /// that can name it learns to exit at once before it learns the balls
    /// (`docs/notes/2026-12-06-issue-47-door-key-and-sparse.md`).
    #[default]
    DoorKey,
    /// On every layout (written `true`).
    Always,
    /// Never: `V` as the paper has it (written `false`).
    Never,
}

impl ExitCandidate {
    /// The exit joins `V` on `layout`.
    pub fn joins(self, layout: &Layout) -> bool {
        match self {
            ExitCandidate::Always => true,
            ExitCandidate::Never => false,
            ExitCandidate::DoorKey => !layout.object_cells().is_empty(),
        }
    }
}

impl Serialize for ExitCandidate {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            ExitCandidate::DoorKey => s.serialize_str("door-key"),
            ExitCandidate::Always => s.serialize_bool(true),
            ExitCandidate::Never => s.serialize_bool(false),
        }
    }
}

impl<'de> Deserialize<'de> for ExitCandidate {
    /// `true`, `false` (the settings of runs before `door-key`) or
    /// `"door-key"`.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Written {
            Flag(bool),
            Name(String),
        }
        match Written::deserialize(d)? {
            Written::Flag(true) => Ok(ExitCandidate::Always),
            Written::Flag(false) => Ok(ExitCandidate::Never),
            Written::Name(n) if n == "door-key" => Ok(ExitCandidate::DoorKey),
            Written::Name(n) => Err(serde::de::Error::custom(format!(
                "exit_candidate {n:?}: expected true, false or \"door-key\""
            ))),
        }
    }
}

/// How the first-layer weights of the inputs `π_g` never saw in training
/// start when an agent is initialised from `π_g` (section 4.4 is silent).
/// Discovery trains `π_g` on the maze's structure without balls, so the
/// planes of the task's objects (balls, keys, locked doors, lava) and of
/// the carried key were zero throughout its training: their weights are
/// still `π_g`'s initial random draw, and copied they make an unfamiliar
/// object act on the copied policy as an arbitrary perturbation (a
/// carried key can turn `π_g` away from its goal).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UnseenInputs {
    /// An object kind `π_g`'s maze lacked starts as floor (the cell as the
    /// world graph's structure has it, [`sim::Layout::structural`]), and
    /// the carried-key plane at zero: the Worker starts out as `π_g`
    /// does on the structure and learns what the objects change.
    #[default]
    AsFloor,
    /// Copied as they are (the behaviour until this setting).
    Copied,
}

/// How the Wide-then-Narrow Worker's second goal plane (`g_n`; the first
/// marks `g_w`) starts under `π_g` initialisation: `π_g` has one goal
/// plane, the Worker two.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NarrowPlaneInit {
    /// A copy of `π_g`'s goal plane: both goals are cells to reach.
    #[default]
    PiGGoal,
    /// Fresh (the behaviour until this setting: the copy was meant but
    /// looked the weights up under a name they do not have).
    Fresh,
}

/// How the policy rows of the actions `π_g` does not have start when the
/// Worker is initialised from `π_g` (section 4.4 is silent: `π_g` only
/// moves).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectActionInit {
    /// Freshly drawn, as any untrained layer: their logits start far below
    /// `π_g`'s trained rows, so the Worker in front of its object goal
    /// steps forward into it and hardly ever picks or opens.
    Fresh,
    /// Copies of `π_g`'s `forward` row: acting on an object goal in front
    /// is what stepping onto a cell goal in front is, so the Worker starts
    /// as ready to pick and open there as to step forward.
    #[default]
    Forward,
}

/// The actions of the Worker (and the baseline) on Door-Key.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DoorKeyActions {
    /// The paper's: Door-Key "adds new actions (`pick` and `open`)" to
    /// left, right and forward — MiniGrid's pickup and toggle; five in all.
    #[default]
    PickOpen,
    /// MiniGrid's six: pickup, drop and toggle (drop can only lose the key).
    Minigrid,
}

impl Default for AgentConfig {
    fn default() -> Self {
        AgentConfig {
            kind: AgentKind::WideNarrow,
            candidates: Candidates::Pivotal,
            traversal: false,
            init_from_gcp: false,
            envs: 32,
            rollout_len: 60,
            horizon: 0,
            window: 0,
            conv_channels: [16, 32],
            hidden: 128,
            worker: A2cConfig::default(),
            manager: A2cConfig::default(),
            goal_reward: 1.0,
            step_penalty: -0.01,
            fine_tune_pi_g: true,
            hand_over: HandOver::default(),
            goal_map: true,
            goal_map_windows: true,
            worker_task_end: WorkerTaskEnd::default(),
            object_goals: true,
            door_key_actions: DoorKeyActions::default(),
            worker_task_share: 0.0,
            count_bonus: 0.0,
            count_bonus_fade: 0,
            ball_shaping: 0.0,
            traverse_outside_window: false,
            traversal_ends_in_window: false,
            narrow_pays_wide: false,
            worker_ball_reward: 0.0,
            eval_actions: EvalActions::default(),
            grad_path: GradPath::RustCore,
            object_action_init: ObjectActionInit::default(),
            exit_candidate: ExitCandidate::default(),
            unseen_inputs: UnseenInputs::default(),
            narrow_plane_init: NarrowPlaneInit::default(),
        }
    }
}

impl AgentConfig {
    /// Checks every value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.envs == 0 {
            return Err(ConfigError::new("envs", "must be at least 1"));
        }
        if self.rollout_len == 0 {
            return Err(ConfigError::new("rollout_len", "must be at least 1"));
        }
        if self.window != 0 && self.window.is_multiple_of(2) {
            return Err(ConfigError::new(
                "window",
                format!("{} must be odd", self.window),
            ));
        }
        if self.conv_channels.iter().any(|&c| c < 1) || self.hidden < 1 {
            return Err(ConfigError::new("hidden", "network sizes must be ≥ 1"));
        }
        if !(self.count_bonus.is_finite() && self.count_bonus >= 0.0) {
            return Err(ConfigError::new(
                "count_bonus",
                format!("{} must be a finite bonus ≥ 0", self.count_bonus),
            ));
        }
        if !(self.ball_shaping.is_finite() && self.ball_shaping >= 0.0) {
            return Err(ConfigError::new(
                "ball_shaping",
                format!("{} must be a finite weight ≥ 0", self.ball_shaping),
            ));
        }
        if !(self.worker_ball_reward.is_finite() && self.worker_ball_reward >= 0.0) {
            return Err(ConfigError::new(
                "worker_ball_reward",
                format!("{} must be a finite reward ≥ 0", self.worker_ball_reward),
            ));
        }
        if !(self.worker_task_share.is_finite() && self.worker_task_share >= 0.0) {
            return Err(ConfigError::new(
                "worker_task_share",
                format!("{} must be a finite share ≥ 0", self.worker_task_share),
            ));
        }
        if !self.goal_reward.is_finite() || !self.step_penalty.is_finite() {
            return Err(ConfigError::new("goal_reward", "rewards must be finite"));
        }
        self.worker.validate("worker")?;
        self.manager.validate("manager")?;
        if self.traversal
            && !(self.kind == AgentKind::WideNarrow && self.candidates != Candidates::All)
        {
            return Err(ConfigError::new(
                "traversal",
                "needs the Wide-then-Narrow agent over V_rand or V_p (the graph of V_all is trivial)",
            ));
        }
        Ok(())
    }

    /// The environment action of each of the Worker's policy outputs on
    /// `task` (MiniGrid numbering): left, right, forward on the MultiGoal
    /// tasks; then pickup and toggle (or pickup, drop, toggle) on Door-Key.
    pub fn worker_actions(&self, task: Task) -> &'static [u8] {
        use sim::action::{DROP, FORWARD, LEFT, PICKUP, RIGHT, TOGGLE};
        match (task.is_multigoal(), self.door_key_actions) {
            (true, _) => &[LEFT, RIGHT, FORWARD],
            (false, DoorKeyActions::PickOpen) => &[LEFT, RIGHT, FORWARD, PICKUP, TOGGLE],
            (false, DoorKeyActions::Minigrid) => &[LEFT, RIGHT, FORWARD, PICKUP, DROP, TOGGLE],
        }
    }

    /// The cells that join the wide-goal candidates `V` beyond its own
    /// (`V_all`'s standable cells, `V_rand`, `V_p`) on `layout`: the task's
    /// objects with [`AgentConfig::object_goals`], the exit with
    /// [`AgentConfig::exit_candidate`].
    pub fn extra_candidates(&self, layout: &Layout) -> Vec<u32> {
        let mut v = if self.object_goals {
            layout.object_cells()
        } else {
            Vec::new()
        };
        if self.exit_candidate.joins(layout) {
            v.extend(
                (0..layout.cells.len() as u32)
                    .filter(|&c| layout.cells[c as usize] == sim::Object::Exit as u8),
            );
        }
        v
    }

    /// The Manager horizon `c`.
    pub fn horizon(&self) -> u32 {
        if self.horizon == 0 {
            (self.rollout_len / 3).max(1) as u32
        } else {
            self.horizon as u32
        }
    }

    /// The narrow window's side for a grid `width` cells wide.
    pub fn window_side(&self, width: usize) -> usize {
        match self.window {
            0 if width > 25 => 7,
            0 => 5,
            n => n,
        }
    }

    /// Goal planes of the Worker's input: none for the baseline, the
    /// subgoal for FN, `g_w` and `g_n` on planes of their own for WN.
    pub fn goal_planes(&self) -> usize {
        match self.kind {
            AgentKind::A2c => 0,
            AgentKind::Feudal => 1,
            AgentKind::WideNarrow => 2,
        }
    }

    /// The Worker's network (the baseline's) with `num_actions` outputs:
    /// the sizes set here, [`Self::goal_planes`] on its input.
    pub fn network(&self, num_actions: usize) -> ActorCriticConfig {
        ActorCriticConfig {
            conv_channels: self.conv_channels,
            hidden: self.hidden,
            num_actions: num_actions as i64,
            goal_planes: self.goal_planes(),
        }
    }

    /// Whether the agent needs a world graph (WN over `V_rand` or `V_p`).
    pub fn needs_graph(&self) -> bool {
        self.kind == AgentKind::WideNarrow && self.candidates != Candidates::All
    }

    /// Whether a run of this agent on `task` needs a discovery run: its
    /// world graph (WN over `V_rand` or `V_p`), its `π_g` (initialisation,
    /// or steering traversal in a stochastic world, section 4.3).
    pub fn needs_discovery(&self, task: Task) -> bool {
        self.needs_graph()
            || self.init_from_gcp
            || (self.traversal && task == Task::MultiGoalStochastic)
    }

    /// A short name: `a2c`, `fn`, `fn-init`, `wn-pivotal-trav-init`, ...
    pub fn name(&self) -> String {
        self.spelled(
            ["a2c", "fn", &format!("wn-{}", self.candidates.name())],
            ["-trav", "-init"],
        )
    }

    /// The agent kind's word (A2C, FN, WN), then the traversal's and the
    /// initialisation's suffix where they are on.
    fn spelled(&self, kinds: [&str; 3], [trav, init]: [&str; 2]) -> String {
        let mut s = match self.kind {
            AgentKind::A2c => kinds[0],
            AgentKind::Feudal => kinds[1],
            AgentKind::WideNarrow => kinds[2],
        }
        .to_string();
        if self.traversal {
            s.push_str(trav);
        }
        if self.init_from_gcp {
            s.push_str(init);
        }
        s
    }

    /// `base` with the agent settings a short name stands for (the inverse
    /// of [`Self::name`]); refused when the name is unknown or not a valid
    /// combination (`a2c-trav`, `wn-all-init` runs as another name).
    pub fn from_name(name: &str, base: &AgentConfig) -> Result<AgentConfig, ConfigError> {
        let mut rest = name;
        let mut strip = |suffix: &str| match rest.strip_suffix(suffix) {
            Some(r) => {
                rest = r;
                true
            }
            None => false,
        };
        let init_from_gcp = strip("-init");
        let traversal = strip("-trav");
        let (kind, candidates) = match rest {
            "a2c" => (AgentKind::A2c, Candidates::All),
            "fn" => (AgentKind::Feudal, Candidates::All),
            "wn-all" => (AgentKind::WideNarrow, Candidates::All),
            "wn-random" => (AgentKind::WideNarrow, Candidates::Random),
            "wn-pivotal" => (AgentKind::WideNarrow, Candidates::Pivotal),
            _ => {
                return Err(ConfigError::new(
                    "configuration",
                    format!(
                        "unknown configuration {name:?}: expected a2c, fn, fn-init or \
                         wn-<all|random|pivotal>[-trav][-init]"
                    ),
                ));
            }
        };
        let cfg = AgentConfig {
            kind,
            candidates,
            traversal,
            init_from_gcp,
            ..base.clone()
        };
        cfg.validate().map_err(|e| {
            ConfigError::new("configuration", format!("configuration {name:?}: {e}"))
        })?;
        if cfg.name() != name {
            return Err(ConfigError::new(
                "configuration",
                format!(
                    "configuration {name:?} is not a valid combination (it would run as {:?})",
                    cfg.name()
                ),
            ));
        }
        Ok(cfg)
    }

    /// The paper's name: `A2C`, `FN + π_g init`,
    /// `WN V_p + traversal + π_g init`, ...
    pub fn label(&self) -> String {
        self.spelled(
            ["A2C", "FN", &format!("WN {}", self.candidates.label())],
            [" + traversal", " + π_g init"],
        )
    }
}

/// What a stage 2 agent takes from stage 1: the world graph over the
/// candidate set (for WN over `V_rand` or `V_p`) and `π_g` (for
/// initialisation and steered traversal).
pub struct WorldGraphInputs {
    /// The graph whose nodes are `V` (`None` for `V_all`).
    pub graph: Option<WorldGraph>,
    /// `π_g` as discovery left it.
    pub gcp: Option<GoalConditionedPolicy>,
}

impl std::fmt::Debug for WorldGraphInputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorldGraphInputs")
            .field("nodes", &self.graph.as_ref().map(|g| g.num_nodes()))
            .field("gcp", &self.gcp.is_some())
            .finish()
    }
}

impl WorldGraphInputs {
    /// A graph over 24 random cells of `layout` and no `π_g` (for the
    /// learner benchmark, which needs no discovery run).
    pub fn random_for_bench(
        layout: &Layout,
        task: Task,
        seed: u64,
    ) -> Result<WorldGraphInputs, LearnerError> {
        let cfg = planner::PlannerConfig {
            candidates: planner::CandidateSet::Random { k: 24 },
            seed,
            task,
            ..planner::PlannerConfig::default()
        };
        Ok(WorldGraphInputs {
            graph: Some(WorldGraph::build(layout, &cfg, &[])?),
            gcp: None,
        })
    }
}

/// How an agent chooses when it is not training (validation, test,
/// `evaluate`). The paper states its protocol (best of 10 validation seeds,
/// scored on 100 test seeds) but not whether the scored policy samples or
/// takes its most likely choices; both are common in A2C codebases.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EvalActions {
    /// Drawn from the policies, as in training.
    #[default]
    Sample,
    /// Each policy's most likely choice: the Worker's (or the baseline's)
    /// action, and the Manager's goal (WN: its most likely wide goal
    /// `g_w`, then the most likely narrow goal `g_n` in that window). In
    /// a deterministic maze a greedy agent can repeat itself to the step
    /// limit: a Manager that names the same goal again after every
    /// horizon, over a Worker whose most likely action there does not
    /// reach it, never gets out.
    Greedy,
}

impl EvalActions {
    /// Chooses greedily on a step that does not train.
    pub fn greedy(self, train: bool) -> bool {
        !train && self == EvalActions::Greedy
    }
}

impl std::str::FromStr for EvalActions {
    type Err = String;

    /// The name `config.toml` writes: `sample` or `greedy`.
    fn from_str(s: &str) -> Result<Self, String> {
        use serde::de::IntoDeserializer;
        let named: Result<Self, serde::de::value::Error> = Self::deserialize(s.into_deserializer());
        named.map_err(|_| format!("{s:?}: expected sample or greedy"))
    }
}

/// How the Worker books a step on which the task ended the environment's
/// episode (the exit, lava) before it reached `g_n`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorkerTaskEnd {
    /// As the end of its goal episode with nothing more to earn. The
    /// Worker is paid only for its goals, so it learns to keep off every
    /// cell that ends the episode unless it is `g_n`: it walks around the
    /// exit, and once the Manager has learnt to collect the balls without
    /// naming the exit, no episode exits again and the Manager never
    /// learns that the exit pays.
    Terminal,
    /// As a cut, like the step limit's: bootstrapped from the Worker's
    /// value of the final state. The episode's end is the Manager's
    /// affair (its reward, its termination); to the Worker the exit is a
    /// cell like any other, neither a goal nor a trap.
    #[default]
    Cut,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The candidates beyond `V`'s own are the layout's: Door-Key's key and
    /// locked door with object goals, its exit with the exit candidate (by
    /// default on Door-Key only), and on a maze without objects the exit
    /// only when it is asked for on every layout.
    #[test]
    fn extra_candidates_are_the_task_objects_and_the_exit_as_set() {
        let dk = sim::Maze::Small.layout(true);
        let at = |x, y| dk.cell_index(x, y) as u32;
        let (key, door, exit) = (at(9, 2), at(6, 9), at(11, 11));
        let mut cfg = AgentConfig::default();
        assert_eq!(cfg.extra_candidates(&dk), vec![key, door, exit]);
        cfg.exit_candidate = ExitCandidate::Never;
        assert_eq!(cfg.extra_candidates(&dk), vec![key, door]);
        cfg.exit_candidate = ExitCandidate::Always;
        cfg.object_goals = false;
        assert_eq!(cfg.extra_candidates(&dk), vec![exit]);
        let plain = sim::Maze::Small.layout(false);
        let plain_exit = plain.cell_index(11, 11) as u32;
        assert!(AgentConfig::default().extra_candidates(&plain).is_empty());
        let always = AgentConfig {
            exit_candidate: ExitCandidate::Always,
            ..AgentConfig::default()
        };
        assert_eq!(always.extra_candidates(&plain), vec![plain_exit]);
    }

    /// The exit candidate is written as runs before `door-key` wrote it
    /// (`true`, `false`), so their summaries still parse and resume; a
    /// word it does not know is refused, naming what it accepts.
    #[test]
    fn the_exit_candidate_reads_the_old_flags_and_door_key() {
        let read = |v: &str| toml::from_str::<AgentConfig>(&format!("exit_candidate = {v}"));
        assert_eq!(read("true").unwrap().exit_candidate, ExitCandidate::Always);
        assert_eq!(read("false").unwrap().exit_candidate, ExitCandidate::Never);
        assert_eq!(
            read("\"door-key\"").unwrap().exit_candidate,
            ExitCandidate::DoorKey
        );
        let err = read("\"sometimes\"").unwrap_err().to_string();
        assert!(err.contains("door-key"), "{err}");
        for c in [
            ExitCandidate::DoorKey,
            ExitCandidate::Always,
            ExitCandidate::Never,
        ] {
            let cfg = AgentConfig {
                exit_candidate: c,
                ..AgentConfig::default()
            };
            let back: AgentConfig = toml::from_str(&toml::to_string(&cfg).unwrap()).unwrap();
            assert_eq!(back.exit_candidate, c);
        }
    }

    /// The gradient path is a setting: absent (every `config.toml` written
    /// before it existed) it is the production path and is not written
    /// back, so those files and their digests read the same; the reference
    /// is written and read back; a retired path is refused by name.
    #[test]
    fn the_gradient_path_is_a_setting_written_only_off_the_production_path() {
        let default = AgentConfig::default();
        assert_eq!(default.grad_path, GradPath::RustCore);
        let text = toml::to_string(&default).unwrap();
        assert!(!text.contains("grad_path"), "{text}");
        let tch = AgentConfig {
            grad_path: GradPath::Tch,
            ..AgentConfig::default()
        };
        let text = toml::to_string(&tch).unwrap();
        assert!(text.contains("grad_path = \"tch\""), "{text}");
        assert_eq!(toml::from_str::<AgentConfig>(&text).unwrap(), tch);
        let err = toml::from_str::<AgentConfig>("grad_path = \"rust-encoder\"")
            .unwrap_err()
            .to_string();
        assert!(err.contains("rust-core") && err.contains("tch"), "{err}");
    }

    /// Every configuration a grid can name parses back to itself, carries
    /// the paper's label, and says whether it needs a discovery run; the
    /// names no agent has are refused.
    #[test]
    fn configuration_names_round_trip_and_carry_the_papers_labels() {
        let base = AgentConfig::default();
        for (name, label, needs) in [
            ("a2c", "A2C", false),
            ("fn", "FN", false),
            ("fn-init", "FN + π_g init", true),
            ("wn-all", "WN V_all", false),
            (
                "wn-random-trav-init",
                "WN V_rand + traversal + π_g init",
                true,
            ),
            ("wn-pivotal-trav", "WN V_p + traversal", true),
            ("wn-pivotal-init", "WN V_p + π_g init", true),
        ] {
            let cfg = AgentConfig::from_name(name, &base).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(cfg.name(), name);
            assert_eq!(cfg.label(), label);
            assert_eq!(cfg.needs_discovery(Task::MultiGoal), needs, "{name}");
        }
        for bad in ["a2c-trav", "wn", "wn-pivotal-init-trav", "dqn"] {
            assert!(AgentConfig::from_name(bad, &base).is_err(), "{bad}");
        }
        let fn_trav = AgentConfig::from_name("fn", &base).map(|c| AgentConfig {
            traversal: true,
            ..c
        });
        assert!(
            fn_trav.is_ok_and(|c| !c.needs_discovery(Task::MultiGoal)
                && c.needs_discovery(Task::MultiGoalStochastic)),
            "steered traversal needs π_g"
        );
    }
}
