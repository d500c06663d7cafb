//! The research levers of the discovery loop: what its settings that are
//! not the paper's do (the settings themselves are in `config.rs`). The
//! loop (the module above) calls into them at fixed points of a round; a
//! lever that is off leaves the round as the paper's sources make it.
//!
//! - goal chains ([`GoalChains`]): trajectories along the shortest routes
//!   the agent knows, a third training source of the latent model;
//! - a goal curriculum ([`GoalCurriculum`]): `π_g`'s training goals
//!   farther away, round by round;
//! - loop erasure of `π_g`'s trajectories
//!   ([`super::DiscoveryConfig::loop_erase_goal_trajectories`]);
//! - the recorded paths replaced by the shortest ones through the
//!   transitions observed ([`super::DiscoveryConfig::shortest_known_paths`]).
//!
//! The goal chains are on by default; the other three are off, as none of
//! them moved `V_p` (`docs/implementation_details.md`, "What issue 12's
//! causes turned out to be").

use rand::SeedableRng;
use rand::rngs::SmallRng;

use super::Discovery;
use super::config::{GoalChains, GoalCurriculum};
use super::walks::{LoopErasedRoute, pose_of};
use crate::batch_env::BatchEnvironment;
use crate::experience::ChainShape;
use crate::vae::{AgentPose, Trajectory};

impl GoalChains {
    /// The shape of one chain.
    pub fn shape(&self) -> ChainShape {
        ChainShape {
            legs: self.legs,
            min_actions: self.min_actions,
            max_actions: self.max_actions,
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

    /// At the start of a round, with every environment just reset: the
    /// recorded paths become the shortest from the start pose through the
    /// transitions observed so far, when
    /// [`super::DiscoveryConfig::shortest_known_paths`] asks.
    pub(super) fn shorten_known_paths(&mut self, env: &dyn BatchEnvironment) {
        if self.state.config.shortest_known_paths {
            let obs = env.observe();
            let start = pose_of(&obs.meta[0], obs.width);
            self.shorten_paths(start);
        }
    }

    /// `π_g`'s trajectories of a round as the latent model gets them:
    /// booked in the agent's experience when the known routes are used
    /// ([`super::DiscoveryConfig::records_experience`]), then with their loops
    /// erased when [`super::DiscoveryConfig::loop_erase_goal_trajectories`] asks
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
    /// ([`super::DiscoveryConfig::shortest_known_paths`]). Breadth-first over
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
    use crate::discovery::DiscoveryConfig;
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
