//! The latent model finds the doorways of a four-room maze as pivotal
//! states (Shang et al. 2019, section 3.1: pivotal states are "the most
//! critical states in recovering action sequences"; `V_p` = the top 20% of
//! states by prior mean).
//!
//! The maze is Sutton's four rooms (13×13, 104 free cells, 4 one-cell
//! doorways). The walker (see [`Maze::walk`]) heads for a random doorway of
//! its room, there passes or turns back, 1–3 times, then ends at a random
//! cell: each doorway visit ends one random leg and starts the next, so the
//! doorways are where the regularity of the actions breaks.
//!
//! Two walkers that did *not* single out doorways, kept here as findings:
//! plain shortest paths between random cells of different rooms (the
//! doorway is then implied by the two ends, and the model rightly kept
//! in-room states that pin down the random move order: one doorway ranked
//! 102nd of 104), and always passing through (a doorway and its two
//! neighbours on the crossing are then equally informative, and the model
//! often kept a neighbour: 11/20 doorways over 5 seeds).
//!
//! The generator is written here on purpose: the test must not depend on the
//! `sim` crate.

use learner::vae::{
    AgentPose, LatentConfig, LatentStats, LatentTrainer, Trajectory, TrajectoryBatch,
};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use std::collections::VecDeque;
use std::time::Instant;
use tch::Device;

const FOUR_ROOMS: &str = "\
#############
#     #     #
#     #     #
#           #
#     #     #
#     #     #
## ####     #
#     ### ###
#     #     #
#     #     #
#           #
#     #     #
#############";

/// Moves as `(dx, dy)`, indexed by action: 0 right, 1 down, 2 left, 3 up
/// (the design's direction numbering).
const MOVES: [(i64, i64); 4] = [(1, 0), (0, 1), (-1, 0), (0, -1)];

struct Maze {
    width: i64,
    free: Vec<bool>,
    doorways: Vec<u32>,
    /// Room of each free non-doorway cell; `usize::MAX` for walls and doorways.
    room: Vec<usize>,
    /// `distance[g][c]`: shortest-path length from `c` to `g` (u32::MAX if
    /// unreachable).
    distance: Vec<Vec<u32>>,
}

impl Maze {
    fn parse(text: &str) -> Self {
        let rows: Vec<&[u8]> = text.lines().map(str::as_bytes).collect();
        let (width, height) = (rows[0].len() as i64, rows.len() as i64);
        let free: Vec<bool> = rows
            .iter()
            .flat_map(|row| row.iter().map(|&c| c != b'#'))
            .collect();
        let mut maze = Self {
            width,
            free,
            doorways: Vec::new(),
            room: Vec::new(),
            distance: Vec::new(),
        };
        // A doorway is a free cell with walls on both sides along one axis
        // and free cells on both sides along the other.
        for cell in 0..(width * height) as u32 {
            let wall = |dx, dy| {
                !maze
                    .neighbour(cell, dx, dy)
                    .is_some_and(|n| maze.free[n as usize])
            };
            let gap_x = wall(-1, 0) && wall(1, 0) && !wall(0, -1) && !wall(0, 1);
            let gap_y = wall(0, -1) && wall(0, 1) && !wall(-1, 0) && !wall(1, 0);
            if maze.free[cell as usize] && (gap_x || gap_y) {
                maze.doorways.push(cell);
            }
        }
        maze.room = maze.rooms();
        maze.distance = (0..maze.free.len() as u32)
            .map(|goal| maze.distances_to(goal))
            .collect();
        maze
    }

    fn neighbour(&self, cell: u32, dx: i64, dy: i64) -> Option<u32> {
        let (x, y) = (
            i64::from(cell) % self.width + dx,
            i64::from(cell) / self.width + dy,
        );
        let height = self.free.len() as i64 / self.width;
        (0..self.width).contains(&x).then_some(())?;
        (0..height)
            .contains(&y)
            .then(|| (y * self.width + x) as u32)
    }

    fn step(&self, cell: u32, action: usize) -> Option<u32> {
        let (dx, dy) = MOVES[action];
        self.neighbour(cell, dx, dy)
            .filter(|&n| self.free[n as usize])
    }

    /// Rooms: connected components of the free cells once doorways are closed.
    fn rooms(&self) -> Vec<usize> {
        let mut room = vec![usize::MAX; self.free.len()];
        let mut next_room = 0;
        for start in 0..self.free.len() as u32 {
            if !self.free[start as usize]
                || self.doorways.contains(&start)
                || room[start as usize] != usize::MAX
            {
                continue;
            }
            let mut stack = vec![start];
            room[start as usize] = next_room;
            while let Some(cell) = stack.pop() {
                for action in 0..4 {
                    if let Some(n) = self.step(cell, action)
                        && !self.doorways.contains(&n)
                        && room[n as usize] == usize::MAX
                    {
                        room[n as usize] = next_room;
                        stack.push(n);
                    }
                }
            }
            next_room += 1;
        }
        room
    }

    fn distances_to(&self, goal: u32) -> Vec<u32> {
        let mut distance = vec![u32::MAX; self.free.len()];
        if !self.free[goal as usize] {
            return distance;
        }
        distance[goal as usize] = 0;
        let mut queue = VecDeque::from([goal]);
        while let Some(cell) = queue.pop_front() {
            for action in 0..4 {
                if let Some(n) = self.step(cell, action)
                    && distance[n as usize] == u32::MAX
                {
                    distance[n as usize] = distance[cell as usize] + 1;
                    queue.push_back(n);
                }
            }
        }
        distance
    }

    fn room_cells(&self) -> Vec<u32> {
        (0..self.free.len() as u32)
            .filter(|&c| self.room[c as usize] != usize::MAX)
            .collect()
    }

    fn free_cells(&self) -> Vec<u32> {
        (0..self.free.len() as u32)
            .filter(|&c| self.free[c as usize])
            .collect()
    }

    /// The room on the other side of `door` from `room`.
    fn across(&self, door: u32, room: usize) -> Option<usize> {
        (0..4)
            .filter_map(|a| self.step(door, a))
            .map(|n| self.room[n as usize])
            .find(|&r| r != usize::MAX && r != room)
    }

    /// The doorways out of `room`, with the room each leads to.
    fn exits(&self, room: usize) -> Vec<(u32, usize)> {
        self.doorways
            .iter()
            .filter(|&&d| {
                (0..4).any(|a| {
                    self.step(d, a)
                        .is_some_and(|n| self.room[n as usize] == room)
                })
            })
            .filter_map(|&d| self.across(d, room).map(|next| (d, next)))
            .collect()
    }

    /// Walks from `tau`'s last state to `target` along a shortest path,
    /// each move drawn uniformly among those that shorten it.
    fn walk_to(&self, tau: &mut Trajectory, target: u32, rng: &mut SmallRng) {
        let distance = &self.distance[target as usize];
        let mut cell = tau.states.last().map_or(target, |s| s.cell);
        while cell != target {
            let shorter: Vec<(usize, u32)> = (0..4)
                .filter_map(|a| self.step(cell, a).map(|n| (a, n)))
                .filter(|&(_, n)| distance[n as usize] < distance[cell as usize])
                .collect();
            let (action, next) = shorter[rng.random_range(0..shorter.len())];
            tau.actions.push(action as u8);
            tau.states.push(AgentPose::at(next));
            cell = next;
        }
    }

    /// A room-to-room walk: from a random room cell the agent heads for one
    /// of its room's doorways (at random), and there either passes into the
    /// next room or turns back (a fair coin); it does so 1 to 3 times, then
    /// walks to a random cell of the room it is in. Moves along the way are
    /// random among those that shorten the path. A doorway is thus where a
    /// leg ends and the next, random one begins: where the regularity of
    /// the actions breaks. The walker has no facing (direction 0).
    fn walk(&self, rng: &mut SmallRng) -> Trajectory {
        let cells = self.room_cells();
        let start = cells[rng.random_range(0..cells.len())];
        let mut tau = Trajectory {
            states: vec![AgentPose::at(start)],
            actions: Vec::new(),
        };
        let mut room = self.room[start as usize];
        for _ in 0..rng.random_range(1..=3) {
            let here = tau.states.last().map_or(start, |s| s.cell);
            let exits: Vec<(u32, usize)> = self
                .exits(room)
                .into_iter()
                .filter(|&(d, _)| d != here)
                .collect();
            let (door, next) = exits[rng.random_range(0..exits.len())];
            self.walk_to(&mut tau, door, rng);
            if rng.random_bool(0.5) {
                room = next;
            }
        }
        let here = tau.states.last().map_or(start, |s| s.cell);
        let ends: Vec<u32> = cells
            .iter()
            .copied()
            .filter(|&c| self.room[c as usize] == room && c != here)
            .collect();
        let end = ends[rng.random_range(0..ends.len())];
        self.walk_to(&mut tau, end, rng);
        tau
    }
}

struct Outcome {
    /// Doorways among the pivotal states (top 20% by prior mean).
    doorways_found: usize,
    /// Rank (0 = most pivotal) of each doorway among the visited cells.
    doorway_ranks: Vec<usize>,
    visited: usize,
    last: LatentStats,
    accuracy: f64,
    /// `(min, max)` of λ1, λ2, λ3 over the last 200 training steps.
    lambda_bands: [(f64, f64); 3],
}

/// The CPU-sized model of these tests.
fn small_config(num_cells: i64) -> LatentConfig {
    // The walker has no facing: one direction, so `prior_mean` averages over
    // exactly the poses that were visited.
    let mut cfg = LatentConfig {
        num_cells,
        num_actions: 4,
        num_directions: 1,
        ..LatentConfig::default()
    };
    cfg.lstm_hidden = 32;
    cfg.state_dim = 16;
    cfg.prior_hidden = 32;
    cfg
}

fn discover(seed: u64, steps: usize, batch_size: usize) -> anyhow::Result<Outcome> {
    // Tiny ops: one intra-op thread avoids spinning worker threads.
    tch::set_num_threads(1);
    let mut rng = SmallRng::seed_from_u64(seed);
    let maze = Maze::parse(FOUR_ROOMS);
    anyhow::ensure!(
        maze.doorways.len() == 4,
        "four doorways, found {:?}",
        maze.doorways
    );
    let cfg = small_config(maze.free.len() as i64);
    let started = Instant::now();
    let mut trainer = LatentTrainer::new(&cfg, Device::Cpu, seed)?;
    let verbose = std::env::var_os("WG_VERBOSE").is_some();
    let mut last = None;
    let mut lambda_bands = [(f64::INFINITY, f64::NEG_INFINITY); 3];
    for step in 0..steps {
        let walks: Vec<Trajectory> = (0..batch_size).map(|_| maze.walk(&mut rng)).collect();
        let stats = trainer.train_step(&TrajectoryBatch::new(&walks, &cfg, Device::Cpu)?);
        if verbose && step % 100 == 0 {
            eprintln!(
                "step {step} ({:.1}s): {stats:?}",
                started.elapsed().as_secs_f64()
            );
        }
        if step + 200 >= steps {
            let lambdas = [stats.lambda_kl, stats.lambda_l0, stats.lambda_transition];
            for (band, value) in lambda_bands.iter_mut().zip(lambdas) {
                *band = (band.0.min(value), band.1.max(value));
            }
        }
        last = Some(stats);
    }
    let model = trainer.model();
    let visited = maze.free_cells();
    let pivotal = model.pivotal_states(&visited, 0.2);
    let means = model.prior_mean(&visited);
    let mut order: Vec<usize> = (0..visited.len()).collect();
    order.sort_by(|&i, &j| means[j].total_cmp(&means[i]));
    if verbose {
        // Prior-mean map: digit = decile of the rank (0 = top 10%), # = wall.
        for y in 0..13 {
            let row: String = (0..13)
                .map(|x| {
                    let cell = (y * 13 + x) as u32;
                    match order.iter().position(|&i| visited[i] == cell) {
                        Some(rank) => char::from(b'0' + (rank * 10 / visited.len()) as u8),
                        None => '#',
                    }
                })
                .collect();
            eprintln!("{row}");
        }
    }
    if verbose {
        // Posterior keep rate per cell over fresh walks: digit = 10·E[1 − P0].
        let walks: Vec<Trajectory> = (0..512).map(|_| maze.walk(&mut rng)).collect();
        let batch = TrajectoryBatch::new(&walks, &cfg, Device::Cpu)?;
        let keep: tch::Tensor = tch::no_grad(|| {
            (1.0_f64 - model.posterior(&batch).prob_zero()) * batch.interior_mask()
        });
        let keep = Vec::<f32>::try_from(keep.flatten(0, -1))?;
        let cells = Vec::<i64>::try_from(batch.cells.flatten(0, -1))?;
        let inside = Vec::<f32>::try_from(batch.interior_mask().flatten(0, -1))?;
        let (mut sum, mut count) = (vec![0.0_f32; 169], vec![0.0_f32; 169]);
        for i in 0..keep.len() {
            sum[cells[i] as usize] += keep[i];
            count[cells[i] as usize] += inside[i];
        }
        for y in 0..13 {
            let row: String = (0..13)
                .map(|x| {
                    let c = y * 13 + x;
                    if count[c] == 0.0 {
                        '#'
                    } else {
                        char::from(b'0' + ((sum[c] / count[c]) * 9.99) as u8)
                    }
                })
                .collect();
            eprintln!("{row}");
        }
    }
    let rank_of = |cell: u32| {
        order
            .iter()
            .position(|&i| visited[i] == cell)
            .unwrap_or(usize::MAX)
    };
    let test_walks: Vec<Trajectory> = (0..256).map(|_| maze.walk(&mut rng)).collect();
    let accuracy = model
        .evaluate(&TrajectoryBatch::new(&test_walks, &cfg, Device::Cpu)?)
        .reconstruction_accuracy;
    Ok(Outcome {
        doorways_found: maze.doorways.iter().filter(|d| pivotal.contains(d)).count(),
        doorway_ranks: maze.doorways.iter().map(|&d| rank_of(d)).collect(),
        visited: visited.len(),
        last: last.ok_or_else(|| anyhow::anyhow!("no training step"))?,
        accuracy,
        lambda_bands,
    })
}

#[test]
fn maze_has_four_doorways_and_four_rooms() {
    let maze = Maze::parse(FOUR_ROOMS);
    assert_eq!(maze.free_cells().len(), 104);
    assert_eq!(
        maze.doorways,
        vec![3 * 13 + 6, 6 * 13 + 2, 7 * 13 + 9, 10 * 13 + 6]
    );
    assert_eq!(
        maze.room.iter().filter(|&&r| r != usize::MAX).max(),
        Some(&3)
    );
    let mut rng = SmallRng::seed_from_u64(0);
    for _ in 0..100 {
        let tau = maze.walk(&mut rng);
        assert_eq!(tau.states.len(), tau.actions.len() + 1);
        for (t, &a) in tau.actions.iter().enumerate() {
            assert_eq!(
                maze.step(tau.states[t].cell, usize::from(a)),
                Some(tau.states[t + 1].cell)
            );
        }
        let crossings = tau
            .states
            .iter()
            .filter(|s| maze.doorways.contains(&s.cell))
            .count();
        assert!(
            (1..=3).contains(&crossings),
            "crosses 1 to 3 doorways, got {crossings}"
        );
    }
}

fn report(seed: u64, outcome: &Outcome, seconds: f64) {
    eprintln!(
        "seed {seed}: {}/4 doorways in the top 20% of {} cells (ranks {:?}), eval accuracy {:.3}, {seconds:.1}s; \
         λ bands over the last 200 steps (KL, L0, LT) {:.3?}; last step {:?}",
        outcome.doorways_found,
        outcome.visited,
        outcome.doorway_ranks,
        outcome.accuracy,
        outcome.lambda_bands,
        outcome.last
    );
}

/// Training budget of the doorway tests: 600 steps of 32 walks (20–40 s on
/// one core in release mode, depending on the machine's load).
const STEPS: usize = 600;
const BATCH: usize = 32;

/// Chance level: a doorway lands in the top 20% of the 104 cells with
/// probability 0.2 under a random ranking, so 3 or more of 4 happens with
/// probability 4·0.2³·0.8 + 0.2⁴ ≈ 0.027. Measured (`doorways_across_seeds`,
/// seeds 1–5, `STEPS` steps): 4, 4, 4, 3 and 4 of 4, a rate of 0.95, the
/// doorways mostly ranked 0–10 of 104.
///
/// It also checks the paper's claim that the multipliers settle on their own
/// from a small start (λ_init = 1e-3): over the last 200 steps every λ stays
/// inside [0.01, 5], away from both clamps (measured, seeds 1–5: λ1 in
/// 0.10–1.37, λ2 in 0.06–3.65, λ3 in 0.55–2.05). They settle into a band,
/// not onto a point: the constraints are estimated on fresh minibatches.
#[test]
fn doorways_rank_among_the_pivotal_states() -> anyhow::Result<()> {
    let started = Instant::now();
    let outcome = discover(1, STEPS, BATCH)?;
    report(1, &outcome, started.elapsed().as_secs_f64());
    assert!(
        outcome.doorways_found >= 3,
        "{}/4 doorways in the top 20% by prior mean (ranks {:?} of {}); chance level 0.2 per doorway, \
         ≥ 3/4 by chance with probability 0.027; measured over seeds 1–5: 19/20 = 0.95",
        outcome.doorways_found,
        outcome.doorway_ranks,
        outcome.visited,
    );
    assert_multipliers_settled(&outcome);
    Ok(())
}

fn assert_multipliers_settled(outcome: &Outcome) {
    for (name, (low, high)) in ["λ1 (KL)", "λ2 (L0)", "λ3 (LT)"]
        .iter()
        .zip(outcome.lambda_bands)
    {
        assert!(
            0.01 <= low && high <= 5.0,
            "{name} over the last 200 steps spans [{low:.4}, {high:.4}], outside [0.01, 5] (clamps 1e-4 and 10)"
        );
    }
}

/// The same experiment over five seeds: `cargo test --release -p learner
/// --test tests -- --ignored doorways_across_seeds --nocapture`.
#[test]
#[ignore = "robustness sweep, about 2 minutes"]
fn doorways_across_seeds() -> anyhow::Result<()> {
    let seeds = [1_u64, 2, 3, 4, 5];
    let mut found = 0;
    for seed in seeds {
        let started = Instant::now();
        let outcome = discover(seed, STEPS, BATCH)?;
        report(seed, &outcome, started.elapsed().as_secs_f64());
        assert_multipliers_settled(&outcome);
        found += outcome.doorways_found;
    }
    let rate = found as f64 / (4 * seeds.len()) as f64;
    eprintln!(
        "doorway rate {rate:.2} over {} seeds (chance 0.20)",
        seeds.len()
    );
    assert!(rate >= 0.6, "doorway rate {rate:.2}, chance 0.20");
    Ok(())
}
