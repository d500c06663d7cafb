//! The goals of `π_g` (section 3.2): where they are drawn
//! ([`GoalSampler`]), and the goal episodes of a batch of environments
//! (`GoalBook`): each step's goal reward and step penalty, the episodes'
//! ends, new goals where one ended, and the recorded trajectories the
//! latent model learns from.
//!
//! Two departures from the paper live here, both always on: training goals
//! are drawn by path distance rather than as walk ends, and recorded goal
//! episodes are chained three to a trajectory (the reasons are at
//! [`GoalSampler`] and `GoalBook`).

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use shm_schemas::{EnvMeta, flags};
use sim::{AutoReset, BallSpawn, Env, EnvConfig, Layout, Object, Pose, Task};

use super::GcpConfig;
use crate::batch_env::ObsView;
use crate::vae::{AgentPose, Trajectory};

/// Draws goals (section 3.2: "sampling goals using the end points of random
/// walks with reasonable length from a given starting state"), two ways:
///
/// - [`GoalSampler::draw`]: the end cell of a random walk of `n` turn-or-
///   forward actions (mostly one to three moves away). Evaluation draws
///   these, so its figures stay comparable.
/// - [`GoalSampler::draw_by_distance`]: a cell drawn uniformly among those
///   whose shortest path from the agent's cell takes 1 to `n` moves (most
///   of them `n/2` or more away, as there are more cells there). Training
///   draws these: the walk ends were too near for `π_g`'s episodes to need
///   any state between their ends, and the goal episodes (`GoalBook`)
///   chain them besides.
///
/// Both work on the layout's geometry: balls and keys count as lifted and
/// doors as open, since goals explore where the agent can go, not what it
/// may carry. A walk that would end the episode (exit, lava) or ends on its
/// own start cell is redrawn; path distances never pass through or end on
/// such cells.
#[derive(Debug)]
pub struct GoalSampler {
    walker: Env,
    width: usize,
    /// Cells a goal may lie on or a path may pass through.
    open: Vec<bool>,
    pub(super) rng: SmallRng,
    /// Breadth-first search scratch: distances from the last start.
    distance: Vec<u32>,
    queue: std::collections::VecDeque<usize>,
}

impl GoalSampler {
    /// Redraws before a walk that keeps returning to its start is accepted
    /// as it is (only in a layout where the agent cannot move).
    const MAX_DRAWS: usize = 64;
    /// The actions a walk draws from.
    const MOVES: [u8; 3] = [sim::action::LEFT, sim::action::RIGHT, sim::action::FORWARD];

    /// A sampler over `layout`'s geometry with its own RNG.
    pub fn new(layout: &Layout, seed: u64) -> GoalSampler {
        let mut geometry = layout.clone();
        for cell in &mut geometry.cells {
            *cell = match Object::from_code(*cell) {
                Some(Object::Ball | Object::Key) => Object::Floor as u8,
                Some(Object::DoorClosed | Object::DoorLocked) => Object::DoorOpen as u8,
                _ => *cell,
            };
        }
        let open = geometry
            .cells
            .iter()
            .map(|&c| {
                !matches!(
                    Object::from_code(c),
                    Some(Object::Wall | Object::Exit | Object::Lava) | None
                )
            })
            .collect();
        let cfg = EnvConfig {
            task: Task::MultiGoal,
            max_steps: u32::MAX,
            balls: BallSpawn::Layout,
            auto_reset: AutoReset::Off,
        };
        GoalSampler {
            walker: Env::new(geometry, cfg, seed, 0),
            width: layout.width,
            open,
            rng: SmallRng::seed_from_u64(seed),
            distance: vec![u32::MAX; layout.cells.len()],
            queue: std::collections::VecDeque::new(),
        }
    }

    /// The end cell of a random walk of `walk_len` moves from `from`, never
    /// `from`'s own cell (unless no walk leaves it).
    pub fn draw(&mut self, from: Pose, walk_len: usize) -> u32 {
        let start = from.y as usize * self.width + from.x as usize;
        let mut end = start;
        for _ in 0..Self::MAX_DRAWS {
            // A fresh copy per walk: nothing of an earlier walk carries over.
            let mut walk = self.walker.clone();
            walk.teleport(from);
            let mut ended = false;
            for _ in 0..walk_len {
                let action = Self::MOVES[self.rng.random_range(0..Self::MOVES.len())];
                if walk.step_meta(action).done() {
                    ended = true;
                    break;
                }
            }
            if !ended {
                end = walk.cell();
                if end != start {
                    break;
                }
            }
        }
        end as u32
    }

    /// A goal cell 1 to `walk_len` moves from `from` by path distance,
    /// never `from`'s own cell unless the agent cannot move.
    pub fn draw_by_distance(&mut self, from: Pose, walk_len: usize) -> u32 {
        let (w, n) = (self.width, self.open.len());
        let start = from.y as usize * w + from.x as usize;
        self.distance.fill(u32::MAX);
        self.distance[start] = 0;
        self.queue.clear();
        self.queue.push_back(start);
        let far = walk_len.max(1) as u32;
        while let Some(i) = self.queue.pop_front() {
            let d = self.distance[i];
            if d == far {
                continue;
            }
            let (x, y) = (i % w, i / w);
            let next = [
                (x + 1 < w).then(|| i + 1),
                (x > 0).then(|| i - 1),
                (i + w < n).then(|| i + w),
                (y > 0).then(|| i - w),
            ];
            for j in next.into_iter().flatten() {
                if self.open[j] && self.distance[j] == u32::MAX {
                    self.distance[j] = d + 1;
                    self.queue.push_back(j);
                }
            }
        }
        let candidates: Vec<usize> = (0..n)
            .filter(|&i| self.distance[i] != u32::MAX && self.distance[i] >= 1)
            .collect();
        if candidates.is_empty() {
            return start as u32;
        }
        candidates[self.rng.random_range(0..candidates.len())] as u32
    }
}

/// One environment's current goal episode.
#[derive(Debug)]
pub(super) struct GoalEpisode {
    /// The goal cell `g`.
    pub(super) goal: u32,
    /// Steps taken towards it.
    pub(super) steps: u32,
    /// Goals reached before this one within `trajectory`.
    pub(super) legs: usize,
    /// Actions of `trajectory` up to the last goal it reached (0 before
    /// the first): where the recorded trajectory ends when this leg fails.
    pub(super) reached: usize,
    /// `(s_t, a_t)` since the chain's first goal was drawn; `states` ends
    /// with the pose the agent stands on now.
    pub(super) trajectory: Trajectory,
}

/// What one step meant for one environment's goal episode.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct GoalStep {
    /// Goal reward plus step penalty (no curiosity).
    pub(super) reward: f32,
    /// The goal episode ended with this step.
    pub(super) goal_done: bool,
    /// The environment's own episode ended (or was reset) with this step.
    pub(super) env_ended: bool,
    /// The agent stands on the goal.
    pub(super) success: bool,
    /// Length of the goal episode that ended.
    pub(super) steps: u32,
    /// The environment's step limit cut the goal episode (no goal reached,
    /// its own time limit not up): its target bootstraps from the final
    /// state's value.
    pub(super) cut: bool,
}

/// The goal episodes of a batch of environments.
///
/// When recording, the goal episodes of one environment are **chained**:
/// a reached goal is followed by the next from where the agent stands,
/// and the trajectory goes on until [`GoalBook::LEGS`] goals were reached
/// or one was missed. A trajectory then crosses rooms, and the states
/// between its ends (the doorways it passes, where one leg turns into the
/// next) carry the information the latent model is meant to find; a
/// single leg's actions follow from its two ends alone. The A2C episodes
/// (rewards, done flags, LSTM resets) are the single goals either way.
///
/// With [`GcpConfig::record_missed_legs`] off, a chain that ends with a
/// missed goal is recorded up to the last goal it reached, and not at all
/// if it reached none: a missed leg is `π_g` wandering, which is what the
/// random walks already give, while the latent model is meant to see
/// `π_g`'s navigation "between close-by states" (section 3.2).
#[derive(Debug)]
pub(super) struct GoalBook {
    pub(super) walk_len: usize,
    pub(super) time_limit: u32,
    pub(super) episodes: Vec<GoalEpisode>,
    /// Trajectories of finished goal episodes (kept only when recording).
    pub(super) finished: Vec<Trajectory>,
    pub(super) record: bool,
    /// Record a chain's missed last leg too ([`GcpConfig::record_missed_legs`]).
    pub(super) record_missed_legs: bool,
}

fn pose_of(meta: &EnvMeta) -> Pose {
    Pose {
        x: meta.x,
        y: meta.y,
        dir: meta.dir,
    }
}

/// The pose of an observation record, as every trajectory source encodes
/// it ([`AgentPose::from_meta`]).
pub(super) fn agent_pose(meta: &EnvMeta, width: usize) -> AgentPose {
    AgentPose::from_meta(meta, width)
}

impl GoalBook {
    /// Goals chained into one recorded trajectory.
    const LEGS: usize = 3;

    pub(super) fn new(walk_len: usize, time_limit: u32, record: bool) -> GoalBook {
        GoalBook {
            walk_len,
            time_limit,
            episodes: Vec::new(),
            finished: Vec::new(),
            record,
            // `GcpConfig::record_missed_legs`'s default: whole chains.
            record_missed_legs: true,
        }
    }

    fn fresh_episode(
        &self,
        sampler: &mut GoalSampler,
        meta: &EnvMeta,
        width: usize,
    ) -> GoalEpisode {
        // Training (recording) goals by path distance, evaluation goals
        // as random-walk ends ([`GoalSampler`]).
        let goal = if self.record {
            sampler.draw_by_distance(pose_of(meta), self.walk_len)
        } else {
            sampler.draw(pose_of(meta), self.walk_len)
        };
        GoalEpisode {
            goal,
            steps: 0,
            legs: 0,
            reached: 0,
            trajectory: Trajectory {
                states: vec![agent_pose(meta, width)],
                actions: Vec::new(),
            },
        }
    }

    /// Makes every environment's goal episode continue from where its agent
    /// stands: draws the first goals, and restarts an episode whose agent
    /// moved since the last step (the environment was stepped by someone
    /// else, e.g. evaluation or path replay in discovery). Returns which
    /// environments restarted (their LSTM state must be reset).
    pub(super) fn sync(&mut self, sampler: &mut GoalSampler, obs: &ObsView<'_>) -> Vec<bool> {
        let width = obs.width;
        if self.episodes.len() != obs.num_envs() {
            self.episodes = obs
                .meta
                .iter()
                .map(|m| self.fresh_episode(sampler, m, width))
                .collect();
            return vec![true; obs.num_envs()];
        }
        let mut restarted = vec![false; obs.num_envs()];
        for (i, meta) in obs.meta.iter().enumerate() {
            let here = agent_pose(meta, width);
            if self.episodes[i].trajectory.states.last() != Some(&here) {
                self.episodes[i] = self.fresh_episode(sampler, meta, width);
                restarted[i] = true;
            }
        }
        restarted
    }

    /// The goal cells, one per environment.
    pub(super) fn goals(&self) -> Vec<u32> {
        self.episodes.iter().map(|e| e.goal).collect()
    }

    /// Books the step that took `actions` and produced `obs`: rewards,
    /// goal-episode ends, trajectories, and new goals where one ended.
    pub(super) fn advance(
        &mut self,
        sampler: &mut GoalSampler,
        obs: &ObsView<'_>,
        actions: &[u8],
        cfg: &GcpConfig,
    ) -> Vec<GoalStep> {
        let width = obs.width;
        let mut out = Vec::with_capacity(self.episodes.len());
        for (i, meta) in obs.meta.iter().enumerate() {
            let env_ended = meta.done() || meta.flags & flags::RESET != 0;
            let here = agent_pose(meta, width);
            let episode = &mut self.episodes[i];
            episode.steps += 1;
            // After an episode end the observation is the next episode's
            // first; arrival is judged on the cell the action led to (the
            // finished episode's final cell). An explicit reset took no
            // action towards the goal.
            let success = if meta.done() {
                meta.end_cell(width) as u32 == episode.goal
            } else {
                !env_ended && here.cell == episode.goal
            };
            if !env_ended {
                episode.trajectory.actions.push(actions[i]);
                episode.trajectory.states.push(here);
            }
            let timed_out = episode.steps >= self.time_limit;
            let goal_done = success || env_ended || timed_out;
            let reward = cfg.step_penalty + if success { cfg.goal_reward } else { 0.0 };
            out.push(GoalStep {
                reward,
                goal_done,
                env_ended,
                success,
                steps: episode.steps,
                cut: meta.truncated() && !success && !timed_out,
            });
            if goal_done {
                let legs = episode.legs + 1;
                let chained = self.record && success && legs < Self::LEGS;
                // The chain goes on: the next goal's steps extend this
                // trajectory.
                let kept = chained.then(|| std::mem::take(&mut episode.trajectory));
                let mut next = self.fresh_episode(sampler, meta, width);
                if let Some(trajectory) = kept {
                    next.legs = legs;
                    next.reached = trajectory.actions.len();
                    next.trajectory = trajectory;
                }
                let mut done = std::mem::replace(&mut self.episodes[i], next);
                if self.record && !chained {
                    if !success && !self.record_missed_legs {
                        // Up to the last goal reached: the missed leg goes.
                        done.trajectory.actions.truncate(done.reached);
                        done.trajectory.states.truncate(done.reached + 1);
                    }
                    if !done.trajectory.actions.is_empty() {
                        self.finished.push(done.trajectory);
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    const ROOM: &str = "#######\n#.....#\n#.....#\n#..>..#\n#.....#\n#....E#\n#######\n";

    pub(in crate::gcp) fn room() -> Layout {
        Layout::parse("room", ROOM).expect("valid layout")
    }

    #[test]
    fn goals_are_walk_ends_away_from_the_agent_within_reach() {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 9);
        let from = Pose { x: 1, y: 1, dir: 0 };
        for (walk_len, by_distance) in (1..=6).flat_map(|n| [(n, false), (n, true)]) {
            let mut farthest = 0;
            for _ in 0..200 {
                let goal = if by_distance {
                    sampler.draw_by_distance(from, walk_len) as usize
                } else {
                    sampler.draw(from, walk_len) as usize
                };
                let (x, y) = (goal % layout.width, goal / layout.width);
                assert_ne!((x, y), (1, 1), "a goal is never the agent's own cell");
                assert_ne!(layout.cells[goal], Object::Wall as u8);
                assert_ne!(
                    layout.cells[goal],
                    Object::Exit as u8,
                    "walks that end the episode are redrawn"
                );
                // At most one cell per forward move (in this open room the
                // path distance is the Manhattan distance).
                assert!(
                    x - 1 + y - 1 <= walk_len,
                    "walk of {walk_len} reached ({x}, {y})"
                );
                farthest = farthest.max(x - 1 + y - 1);
            }
            if by_distance {
                // The room's far corner is 8 moves away: goals reach `walk_len`.
                assert_eq!(farthest, walk_len, "by distance, walk of {walk_len}");
            }
        }
        // Same seed, same goals.
        let draws = |seed| {
            let mut s = GoalSampler::new(&layout, seed);
            (0..20).map(|_| s.draw(from, 4)).collect::<Vec<_>>()
        };
        assert_eq!(draws(3), draws(3));
    }

    /// The observation of one environment of [`room`] whose agent stands
    /// on `cell` facing right, handed to `f`.
    fn with_obs<R>(cell: u32, f: impl FnOnce(&ObsView<'_>) -> R) -> R {
        let layout = room();
        let w = layout.width as u32;
        let meta = [EnvMeta {
            x: (cell % w) as u16,
            y: (cell / w) as u16,
            carrying: EnvMeta::CARRYING_NOTHING,
            ..EnvMeta::EMPTY
        }];
        let cells = vec![0u8; layout.cells.len()];
        f(&crate::a2c::input::test_view(
            &cells,
            &meta,
            layout.width,
            layout.height,
        ))
    }

    /// Books a forward step after which the agent stands on `cell`.
    fn book_step(book: &mut GoalBook, sampler: &mut GoalSampler, cell: u32) -> GoalStep {
        with_obs(cell, |obs| {
            book.advance(sampler, obs, &[sim::action::FORWARD], &GcpConfig::default())[0]
        })
    }

    /// Records what a chain that reaches one goal, then misses the next,
    /// leaves for the latent model: (start cell, first goal, recorded).
    fn chain_with_a_missed_leg(record_missed_legs: bool) -> (u32, u32, Vec<Trajectory>) {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 5);
        let mut book = GoalBook {
            record_missed_legs,
            ..GoalBook::new(3, 4, true)
        };
        let start = 3 * layout.width as u32 + 3;
        with_obs(start, |obs| book.sync(&mut sampler, obs));
        let first = book.goals()[0];
        assert_ne!(first, start);
        assert!(book_step(&mut book, &mut sampler, first).success);
        assert!(
            book.finished.is_empty(),
            "the chain goes on after a reached goal"
        );
        // The second goal is never reached: the agent stays on the first
        // goal's cell (a goal is never the agent's own cell) until the
        // time limit of 4 steps.
        for t in 0..4 {
            let step = book_step(&mut book, &mut sampler, first);
            assert_eq!(step.goal_done, t == 3);
            assert!(!step.success);
        }
        (start, first, std::mem::take(&mut book.finished))
    }

    #[test]
    fn a_chain_is_recorded_up_to_its_last_reached_goal() {
        let (start, first, recorded) = chain_with_a_missed_leg(false);
        assert_eq!(recorded.len(), 1);
        let cells: Vec<u32> = recorded[0].states.iter().map(|s| s.cell).collect();
        assert_eq!(cells, vec![start, first]);
        assert_eq!(recorded[0].actions, vec![sim::action::FORWARD]);

        // With the missed legs kept, the four steps towards the second goal
        // are part of it.
        let (_, _, recorded) = chain_with_a_missed_leg(true);
        assert_eq!(recorded.len(), 1);
        assert_eq!(recorded[0].actions.len(), 5);
        assert_eq!(recorded[0].states.len(), 6);
    }

    #[test]
    fn a_chain_that_reaches_no_goal_is_not_recorded() {
        let layout = room();
        let mut sampler = GoalSampler::new(&layout, 8);
        let mut book = GoalBook {
            record_missed_legs: false,
            ..GoalBook::new(3, 2, true)
        };
        let start = 2 * layout.width as u32 + 2;
        with_obs(start, |obs| book.sync(&mut sampler, obs));
        assert!(!book_step(&mut book, &mut sampler, start).goal_done);
        assert!(book_step(&mut book, &mut sampler, start).goal_done);
        assert!(book.finished.is_empty());
    }
}
