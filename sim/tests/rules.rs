//! Movement, pickup, drop, toggle and door rules, and every task's rewards
//! and terminations, on small hand-made layouts.

use sim::action::*;
use sim::{AutoReset, BallSpawn, Env, EnvConfig, EnvMeta, Layout, Object, Pose, Task, flags};

fn env(text: &str, task: Task) -> Env {
    let layout = Layout::parse("test", text).expect("valid layout");
    let cfg = EnvConfig {
        task,
        max_steps: 100,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::Off,
    };
    Env::new(layout, cfg, 7, 0)
}

fn run(env: &mut Env, actions: &[u8]) -> Vec<EnvMeta> {
    actions.iter().map(|&a| env.step_meta(a)).collect()
}

fn at(env: &Env) -> (u16, u16, u8) {
    let p = env.pose();
    (p.x, p.y, p.dir)
}

const CLOSE: f32 = 1e-5;

#[test]
fn turning_and_moving_follow_minigrid_directions() {
    let mut e = env("#####\n#...#\n#.>.#\n#..E#\n#####\n", Task::MultiGoal);
    assert_eq!(at(&e), (2, 2, 0));
    e.step_meta(FORWARD);
    assert_eq!(at(&e), (3, 2, 0), "right is +x");
    e.step_meta(RIGHT);
    assert_eq!(at(&e).2, 1, "right turn: right -> down");
    e.step_meta(LEFT);
    e.step_meta(LEFT);
    assert_eq!(at(&e).2, 3, "two left turns: right -> up");
    e.step_meta(FORWARD);
    assert_eq!(at(&e), (3, 1, 3), "up is -y");
    e.step_meta(FORWARD);
    assert_eq!(at(&e), (3, 1, 3), "the wall blocks");
    for _ in 0..4 {
        e.step_meta(LEFT);
    }
    assert_eq!(at(&e).2, 3, "four turns are a full circle");
}

#[test]
fn walls_keys_and_closed_doors_block_forward_open_doors_do_not() {
    // Agent faces a key, then a closed door, then an open door.
    let mut e = env("#######\n#>K..E#\n#######\n", Task::DoorKey);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 1, "a key blocks");
    let mut e = env("#######\n#>C..E#\n#######\n", Task::DoorKey);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 1, "a closed door blocks");
    e.step_meta(TOGGLE);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 2, "an opened door lets through");
    let mut e = env("#######\n#>O..E#\n#######\n", Task::DoorKey);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 2, "an open door is passable");
    // Toggling an open door in front closes it.
    let mut e = env("#######\n#>O..E#\n#######\n", Task::DoorKey);
    e.step_meta(TOGGLE);
    assert_eq!(e.grid()[9], Object::DoorClosed as u8);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 1, "closed again, blocks again");
}

#[test]
fn pickup_and_drop_rules() {
    let mut e = env("#######\n#>K.BE#\n#######\n", Task::DoorKey);
    e.step_meta(PICKUP);
    assert_eq!(e.carrying(), Some(Object::Key));
    assert_eq!(e.grid()[9], Object::Floor as u8, "the key left the grid");
    e.step_meta(FORWARD);
    e.step_meta(FORWARD);
    assert_eq!(at(&e).0, 3);
    e.step_meta(PICKUP);
    assert_eq!(
        e.carrying(),
        Some(Object::Key),
        "hands full: the ball stays"
    );
    assert_eq!(e.grid()[11], Object::Ball as u8);
    // Drop only onto empty floor.
    e.step_meta(DROP);
    assert_eq!(e.carrying(), Some(Object::Key), "cannot drop onto a ball");
    e.step_meta(LEFT);
    e.step_meta(LEFT);
    e.step_meta(DROP);
    assert_eq!(e.carrying(), None);
    assert_eq!(e.grid()[9], Object::Key as u8);
    e.step_meta(DROP);
    assert_eq!(e.carrying(), None, "drop with empty hands is a no-op");
}

#[test]
fn locked_doors_need_the_key_and_door_key_rewards_once() {
    let mut e = env("########\n#K>D..E#\n########\n", Task::DoorKey);
    let m = e.step_meta(TOGGLE);
    assert_eq!(
        e.grid()[11],
        Object::DoorLocked as u8,
        "no key: stays locked"
    );
    assert!((m.reward - -0.01).abs() < CLOSE);
    run(&mut e, &[LEFT, LEFT, PICKUP, RIGHT, RIGHT]);
    assert_eq!(e.carrying(), Some(Object::Key));
    let m = e.step_meta(TOGGLE);
    assert_eq!(
        e.grid()[11],
        Object::DoorOpen as u8,
        "the key unlocks and opens"
    );
    assert!(
        (m.reward - 0.99).abs() < CLOSE,
        "door opened: +1 - 0.01, got {}",
        m.reward
    );
    assert_eq!(e.carrying(), Some(Object::Key), "the key is kept");
    let m = e.step_meta(TOGGLE);
    assert_eq!(
        e.grid()[11],
        Object::DoorClosed as u8,
        "an unlocked door closes"
    );
    assert!((m.reward - -0.01).abs() < CLOSE);
    let m = e.step_meta(TOGGLE);
    assert!((m.reward - -0.01).abs() < CLOSE, "re-opening pays nothing");
    let ms = run(&mut e, &[FORWARD, FORWARD, FORWARD, FORWARD]);
    let last = ms.last().unwrap();
    assert!(last.terminated() && !last.truncated());
    assert!((last.reward - 0.99).abs() < CLOSE, "exit: +1");
    // 13 actions: 2 rewards of +1, 13 penalties of 0.01.
    let total: f32 = 2.0 - 0.01 * 13.0;
    assert!(
        (last.episode_return - total).abs() < 1e-4,
        "{} vs {total}",
        last.episode_return
    );
    assert_eq!(last.episode_len, 13);
}

#[test]
fn multigoal_collects_balls_by_stepping_on_them_and_ends_at_the_exit() {
    let mut e = env("#######\n#>BB.E#\n#######\n", Task::MultiGoal);
    let ms = run(&mut e, &[FORWARD, FORWARD, FORWARD, FORWARD]);
    let r: Vec<f32> = ms.iter().map(|m| m.reward).collect();
    assert!(
        (r[0] - 0.99).abs() < CLOSE && (r[1] - 0.99).abs() < CLOSE,
        "{r:?}"
    );
    assert!((r[2] - -0.01).abs() < CLOSE);
    assert!((r[3] - 0.99).abs() < CLOSE);
    assert_eq!(ms[3].flags & flags::DONE, flags::TERMINATED);
    assert_eq!(ms[3].balls, 2);
    assert_eq!(e.grid()[9], Object::Floor as u8, "a collected ball is gone");
}

#[test]
fn multigoal_sparse_pays_only_at_the_exit_in_proportion_to_balls() {
    let mut e = env("########\n#>B.B.E#\n########\n", Task::MultiGoalSparse);
    let ms = run(&mut e, &[FORWARD, FORWARD, FORWARD, FORWARD, FORWARD]);
    for m in &ms[..4] {
        assert!(
            (m.reward - -0.01).abs() < CLOSE,
            "no reward before the exit"
        );
    }
    // Exit with 2 of 2 balls: 2/2 = 1.
    assert!((ms[4].reward - 0.99).abs() < CLOSE, "{}", ms[4].reward);
    let mut e = env(
        "########\n#>....E#\n#.B.B..#\n########\n",
        Task::MultiGoalSparse,
    );
    // Down to (1,2), right onto the ball at (2,2), up to (2,1), then right to the exit.
    let ms = run(
        &mut e,
        &[
            RIGHT, FORWARD, LEFT, FORWARD, LEFT, FORWARD, RIGHT, FORWARD, FORWARD, FORWARD, FORWARD,
        ],
    );
    let last = ms.iter().find(|m| m.done()).expect("reached the exit");
    assert_eq!(last.balls, 1);
    assert!(
        (last.reward - (0.5 - 0.01)).abs() < CLOSE,
        "1 of 2 balls: 0.5, got {}",
        last.reward
    );
}

#[test]
fn multigoal_stochastic_moves_lava_every_step_and_lava_ends_with_minus_half() {
    let layout = Layout::parse("t", "#######\n#>....#\n#....E#\n#######\n").unwrap();
    let cfg = EnvConfig {
        task: Task::MultiGoalStochastic,
        max_steps: 100,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::Off,
    };
    let mut e = Env::new(layout.clone(), cfg, 3, 0);
    let lava_at = |e: &Env| e.grid().iter().position(|&c| c == Object::Lava as u8);
    let mut positions = std::collections::HashSet::new();
    for _ in 0..40 {
        let l = lava_at(&e).expect("one lava block at all times");
        assert_eq!(
            e.grid()
                .iter()
                .filter(|&&c| c == Object::Lava as u8)
                .count(),
            1
        );
        assert_ne!(l, e.cell(), "lava never spawns under the agent");
        positions.insert(l);
        e.step_meta(LEFT);
    }
    assert!(positions.len() > 3, "the lava moves: {positions:?}");
    // Walk into the lava: find a seed whose lava is right in front after one turn-in-place step.
    for seed in 0..500 {
        let mut e = Env::new(layout.clone(), cfg, seed, 0);
        let m = e.step_meta(DONE);
        assert!(!m.done());
        if lava_at(&e) == Some(e.cell() + 1) {
            let m = e.step_meta(FORWARD);
            assert!(m.terminated(), "lava terminates");
            assert!((m.reward - (-0.5 - 0.01)).abs() < CLOSE, "{}", m.reward);
            return;
        }
    }
    panic!("no seed put lava in front of the agent");
}

#[test]
fn truncation_is_reported_apart_from_termination_and_auto_reset_restarts() {
    let layout = Layout::parse("t", "#####\n#>.E#\n#####\n").unwrap();
    let cfg = EnvConfig {
        task: Task::MultiGoal,
        max_steps: 3,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    };
    let mut e = Env::new(layout, cfg, 1, 0);
    let ms = run(&mut e, &[LEFT, LEFT, LEFT]);
    assert_eq!(ms[2].flags & flags::DONE, flags::TRUNCATED);
    assert!(ms[2].flags & flags::RESET != 0, "same-step auto-reset");
    assert_eq!(ms[2].episode_len, 3);
    assert!((ms[2].episode_return - -0.03).abs() < CLOSE);
    assert_eq!(
        (ms[2].x, ms[2].y, ms[2].dir),
        (1, 1, 0),
        "the returned pose is the new episode's start"
    );
    assert_eq!(e.steps(), 0);
    // Terminating on the last allowed step is a termination, not a truncation.
    let mut e2 = Env::new(
        Layout::parse("t", "#####\n#>.E#\n#####\n").unwrap(),
        EnvConfig {
            max_steps: 2,
            ..cfg
        },
        1,
        0,
    );
    let ms = run(&mut e2, &[FORWARD, FORWARD]);
    assert_eq!(ms[1].flags & flags::DONE, flags::TERMINATED);
}

#[test]
fn auto_reset_off_holds_the_final_state_until_reset() {
    let mut e = env("#####\n#>.E#\n#####\n", Task::MultiGoal);
    let ms = run(&mut e, &[FORWARD, FORWARD, FORWARD, LEFT]);
    assert!(ms[1].terminated());
    assert!(
        ms[2].terminated() && ms[2].reward == 0.0,
        "a finished env repeats its final flags"
    );
    assert_eq!((ms[3].x, ms[3].y), (3, 1));
    let mut cells = vec![0; 15];
    let mut meta = EnvMeta::EMPTY;
    e.reset(&mut cells, &mut meta);
    assert_eq!(meta.flags, flags::RESET);
    assert_eq!((meta.x, meta.y), (1, 1));
    assert!(!e.is_done());
}

#[test]
fn random_balls_spawn_on_free_floor_each_episode() {
    let layout = sim::Maze::Small.layout(false);
    let cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
    let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize);
    let mut seen = std::collections::HashSet::new();
    for i in 0..20 {
        let e = Env::new(layout.clone(), cfg, 11, i);
        let balls: Vec<usize> = (0..e.grid().len())
            .filter(|&c| e.grid()[c] == Object::Ball as u8)
            .collect();
        assert_eq!(balls.len(), 5, "five balls");
        for &b in &balls {
            assert_eq!(layout.cells[b], Object::Floor as u8, "balls only on floor");
            assert_ne!(b, start);
        }
        seen.insert(balls);
    }
    assert!(
        seen.len() > 15,
        "different environments get different balls"
    );
}

#[test]
fn teleport_places_the_agent() {
    let mut e = env("######\n#>..E#\n######\n", Task::MultiGoal);
    e.teleport(Pose { x: 3, y: 1, dir: 0 });
    let m = e.step_meta(FORWARD);
    assert!(m.terminated());
}

#[test]
fn minigrid_encoding_includes_the_agent() {
    let e = env("#####\n#>.E#\n#####\n", Task::MultiGoal);
    let enc = e.minigrid_obs();
    assert_eq!(enc[6], [10, 0, 0], "agent: object 10, red, facing right");
    assert_eq!(enc[8], [8, 1, 0], "exit is MiniGrid's green goal");
    assert_eq!(enc[0], [2, 5, 0], "grey wall");
}

#[test]
fn the_reset_action_starts_a_new_episode_on_demand() {
    let mut e = env("######\n#>..E#\n######\n", Task::MultiGoal);
    run(&mut e, &[FORWARD, RIGHT]);
    let m = e.step_meta(RESET);
    assert_eq!(m.flags, flags::RESET, "no DONE flags, only RESET");
    assert_eq!(m.reward, 0.0);
    assert_eq!((m.x, m.y, m.dir), (1, 1, 0), "back at the start");
    assert_eq!(e.steps(), 0);
    // It also revives a finished environment under AutoReset::Off.
    run(&mut e, &[FORWARD, FORWARD, FORWARD]);
    assert!(e.is_done());
    e.step_meta(RESET);
    assert!(!e.is_done());
}
