//! The research levers of the discovery loop: its settings that are not
//! the paper's, and the code that carries them out. The loop (the module
//! above) calls into them at fixed points of a round; a lever that is off
//! leaves the round as the paper's sources make it.
//!
//! - goal chains ([`GoalChains`]): trajectories along the shortest routes
//!   the agent knows, a third training source of the latent model;
//! - a goal curriculum ([`GoalCurriculum`]): `π_g`'s training goals
//!   farther away, round by round;
//! - loop erasure of `π_g`'s trajectories
//!   ([`DiscoveryConfig::loop_erase_goal_trajectories`]);
//! - the recorded paths replaced by the shortest ones through the
//!   transitions observed ([`DiscoveryConfig::shortest_known_paths`]).
//!
//! The goal chains are on by default; the other three are off, as none of
//! them moved `V_p` (`docs/implementation_details.md`, "What issue 12's
//! causes turned out to be").

use rand::SeedableRng;
use rand::rngs::SmallRng;
use serde::{Deserialize, Serialize};

use super::walks::LoopErasedRoute;
use super::{Discovery, DiscoveryConfig};
use crate::error::LearnerError;
use crate::experience::ChainShape;
use crate::vae::{AgentPose, Trajectory};

impl DiscoveryConfig {
    /// True when the loop books the transitions it observes (the known
    /// routes are used).
    pub fn records_experience(&self) -> bool {
        self.shortest_known_paths || self.goal_chains.per_round > 0
    }
}

/// Goal chains: trajectories that reach `legs` goals in turn, each along
/// a shortest route through the transitions the agent has observed, ties
/// broken at random ([`crate::experience`]). They stand for what a trained
/// `π_g` does (section 3.2), whose trajectories the latent model learns
/// from (section 3.1): at this implementation's budget `π_g` reaches
/// goals within a room only (`docs/implementation_details.md`, "Where
/// stage 1 departs from the paper"), while a trajectory whose legs cross
/// rooms is what the doorways explain. The chains join the walks and
/// `π_g`'s episodes as a third source of the training buffer, and
/// `batch_share` of every latent batch is drawn from them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalChains {
    /// Chains drawn per round (0: none, the loop of the paper's sources
    /// alone).
    pub per_round: usize,
    /// Goals reached in turn by one chain.
    pub legs: usize,
    /// Fewest actions from one goal (or the chain's start) to the next
    /// along the shortest known route.
    pub min_actions: u32,
    /// Most actions from one goal to the next.
    pub max_actions: u32,
    /// Share of every latent-model batch drawn from the chains; the rest
    /// is split evenly between the walks and `π_g`'s episodes.
    pub batch_share: f64,
}

impl Default for GoalChains {
    fn default() -> Self {
        GoalChains {
            per_round: 512,
            legs: 1,
            min_actions: 8,
            // Beyond the farthest cell of any embedded maze: goals anywhere
            // at least `min_actions` away.
            max_actions: 1000,
            batch_share: 0.75,
        }
    }
}

impl GoalChains {
    /// The shape of one chain.
    pub fn shape(&self) -> ChainShape {
        ChainShape {
            legs: self.legs,
            min_actions: self.min_actions,
            max_actions: self.max_actions,
        }
    }

    pub(super) fn validate(&self) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: &str| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if self.per_round > 0 && self.legs == 0 {
            return bad("goal_chains.legs", "must be at least 1");
        }
        if self.min_actions == 0 || self.max_actions < self.min_actions {
            return bad(
                "goal_chains.min_actions",
                "must be at least 1 and at most goal_chains.max_actions",
            );
        }
        if !(0.0..1.0).contains(&self.batch_share) {
            return bad("goal_chains.batch_share", "must be in [0, 1)");
        }
        Ok(())
    }
}

/// A curriculum on the distance of `π_g`'s training goals. The paper draws
/// goals at "the end points of random walks with reasonable length"
/// (section 3.2) and leaves the length open. Near goals are what `π_g`
/// learns first, far goals are what the latent model needs: a trajectory
/// whose legs cross rooms is explained by the doorways it passes, a short
/// one by its two ends alone (section 3.1). So goals start within
/// [`crate::gcp::GcpConfig::goal_walk_len`] moves, and after each round in which `π_g`
/// reached at least `success_threshold` of its training goals the
/// distance grows by `step` moves, up to `max_moves` (`step = 0`, the
/// default, keeps it at `goal_walk_len`). The distance is part of the
/// checkpoint, so a resumed run goes on at the distance it reached.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalCurriculum {
    /// Moves added to the goal distance after a round that passed
    /// `success_threshold` (0: the distance stays at `goal_walk_len`).
    pub step: usize,
    /// Training success rate of a round (mean over its A2C iterations) at
    /// which the next round's goals lie `step` moves farther.
    pub success_threshold: f64,
    /// The farthest goal distance, in moves.
    pub max_moves: usize,
}

impl Default for GoalCurriculum {
    fn default() -> Self {
        GoalCurriculum {
            // Off (see `DiscoveryConfig::default`); `step = 2` turns it on.
            step: 0,
            success_threshold: 0.5,
            max_moves: 16,
        }
    }
}

impl GoalCurriculum {
    /// The distance of the round after one at `moves` whose training
    /// success rate was `success`.
    pub fn next(&self, moves: usize, success: f64) -> usize {
        if success >= self.success_threshold {
            (moves + self.step).min(self.max_moves.max(moves))
        } else {
            moves
        }
    }

    pub(super) fn validate(&self, start: usize) -> Result<(), LearnerError> {
        let bad = |field: &'static str, reason: String| {
            Err(LearnerError::Config(crate::ConfigError::new(field, reason)))
        };
        if !(self.success_threshold > 0.0 && self.success_threshold <= 1.0) {
            return bad(
                "goal_curriculum.success_threshold",
                format!("{} must be in (0, 1]", self.success_threshold),
            );
        }
        if self.step > 0 && self.max_moves < start {
            return bad(
                "goal_curriculum.max_moves",
                format!(
                    "{} must be at least gcp.goal_walk_len ({start})",
                    self.max_moves
                ),
            );
        }
        Ok(())
    }
}

impl Discovery {
    /// Sets `π_g`'s goal distance for this round and returns it: where the
    /// [`GoalCurriculum`] left it, `gcp.goal_walk_len` before the first
    /// round (or without a curriculum, which never moves it).
    pub(super) fn start_goal_distance(&mut self) -> usize {
        let goal_distance = match self.state.goal_distance {
            0 => self.state.config.gcp.goal_walk_len,
            d => d,
        };
        self.gcp.set_goal_distance(goal_distance);
        goal_distance
    }

    /// `π_g`'s trajectories of a round as the latent model gets them:
    /// booked in the agent's experience when the known routes are used
    /// ([`DiscoveryConfig::records_experience`]), then with their loops
    /// erased when [`DiscoveryConfig::loop_erase_goal_trajectories`] asks
    /// (dropping any left without an action); as they are otherwise.
    pub(super) fn goal_trajectories_for_latent(
        &mut self,
        goal_trajectories: Vec<Trajectory>,
    ) -> Vec<Trajectory> {
        if self.state.config.records_experience() {
            for t in &goal_trajectories {
                self.state.experience.observe_trajectory(t);
            }
        }
        if self.state.config.loop_erase_goal_trajectories {
            goal_trajectories
                .iter()
                .map(loop_erased)
                .filter(|t| !t.actions.is_empty())
                .collect()
        } else {
            goal_trajectories
        }
    }

    /// This round's goal chains ([`GoalChains`]), drawn from the
    /// experience with an RNG of their own seeded from `(seed, round)`.
    pub(super) fn goal_chains(&self, round: u32) -> Vec<Trajectory> {
        let c = &self.state.config.goal_chains;
        if c.per_round == 0 {
            return Vec::new();
        }
        let seed = sim::env_seed(self.state.config.seed, 0x200_0000 + u64::from(round));
        let mut rng = SmallRng::seed_from_u64(seed);
        let routes = self.state.experience.routes();
        (0..c.per_round)
            .filter_map(|_| routes.chain(c.shape(), &mut rng))
            .collect()
    }

    /// Replaces each recorded path by the shortest action sequence from
    /// `start` through the observed transitions, where that is shorter
    /// ([`DiscoveryConfig::shortest_known_paths`]). Breadth-first over
    /// poses, actions in ascending order, so the result is a function of
    /// the experience alone.
    pub(super) fn shorten_paths(&mut self, start: AgentPose) {
        for (cell, path) in self.state.experience.shortest_paths_from(start) {
            let known = self.state.paths.get(&cell).map_or(usize::MAX, Vec::len);
            if path.len() < known {
                self.state.paths.insert(cell, path);
            }
        }
    }
}

/// `t` with its loops erased ([`LoopErasedRoute`]): same first and last
/// pose, every pose at most once.
fn loop_erased(t: &Trajectory) -> Trajectory {
    let mut route = LoopErasedRoute::default();
    let Some(&start) = t.states.first() else {
        return t.clone();
    };
    route.reset(start);
    for (&a, &pose) in t.actions.iter().zip(&t.states[1..]) {
        route.push(a, pose);
    }
    route.trajectory()
}

#[cfg(test)]
mod tests {
    use sim::Layout;

    use super::*;
    use crate::experience::test_support::{pose, walked};

    #[test]
    fn loop_erasure_keeps_the_ends_and_drops_the_detours() {
        use sim::action::{FORWARD, LEFT, RIGHT};
        // Forward, a turn left and back (a loop on the pose), into a wall
        // (no move: a loop of one step), forward again.
        let t = Trajectory {
            states: vec![
                pose(1, 0),
                pose(2, 0),
                pose(2, 3),
                pose(2, 0),
                pose(2, 0),
                pose(3, 0),
            ],
            actions: vec![FORWARD, LEFT, RIGHT, FORWARD, FORWARD],
        };
        let erased = loop_erased(&t);
        assert_eq!(erased.states, vec![pose(1, 0), pose(2, 0), pose(3, 0)]);
        assert_eq!(erased.actions, vec![FORWARD, FORWARD]);
        // A trajectory without loops is left as it is.
        assert_eq!(loop_erased(&erased), erased);
    }

    #[test]
    fn recorded_paths_become_the_shortest_through_observed_transitions() {
        use sim::action::{FORWARD, LEFT, RIGHT};
        let layout = Layout::parse("room", "#####\n#>..#\n#..E#\n#####\n").expect("layout");
        let mut d = Discovery::new(DiscoveryConfig::default(), &layout, 1, 3).expect("discovery");
        // The room of `walked`: the top row, and a detour below.
        d.state.experience = walked();
        let walked = vec![FORWARD, LEFT, RIGHT, FORWARD, RIGHT, RIGHT, LEFT, FORWARD];
        d.state.paths.insert(13, walked);
        d.state.paths.insert(11, vec![FORWARD; 9]);
        d.state.paths.insert(7, vec![FORWARD]);
        d.shorten_paths(pose(6, 0));
        assert_eq!(d.state.paths[&13], vec![FORWARD, FORWARD, RIGHT, FORWARD]);
        assert_eq!(d.state.paths[&11], vec![RIGHT, FORWARD]);
        assert_eq!(d.state.paths[&8], vec![FORWARD, FORWARD]);
        // A recorded path as short as the known one is kept.
        assert_eq!(d.state.paths[&7], vec![FORWARD]);
    }

    #[test]
    fn the_goal_distance_grows_with_success_up_to_its_cap() {
        let c = GoalCurriculum {
            step: 2,
            success_threshold: 0.5,
            max_moves: 9,
        };
        assert_eq!(c.next(6, 0.49), 6);
        assert_eq!(c.next(6, 0.5), 8);
        assert_eq!(c.next(8, 0.9), 9);
        assert_eq!(c.next(9, 1.0), 9);
        let off = GoalCurriculum { step: 0, ..c };
        assert_eq!(off.next(6, 1.0), 6);
    }
}
