//! The final state of a finished episode under same-step auto-reset
//! (issue 24): the step that ends an episode returns the next episode's
//! first observation, and beside it the pose the action led to
//! (`EnvMeta::end_*`) and the grid the episode ended on (the final cells).

use std::collections::VecDeque;

use sim::action::*;
use sim::{
    AutoReset, BallSpawn, BatchEnv, Env, EnvConfig, EnvMeta, Layout, Maze, Object, StepBuffers,
    Task, flags,
};

/// A byte no cell code uses: final cells still holding it were not written.
const UNWRITTEN: u8 = 0xEE;

fn config(task: Task, max_steps: u32) -> EnvConfig {
    EnvConfig {
        task,
        max_steps,
        balls: BallSpawn::Layout,
        auto_reset: AutoReset::SameStep,
    }
}

/// `(x, y, dir, carrying)` of the observation.
fn pose(m: &EnvMeta) -> (u16, u16, u8, u8) {
    (m.x, m.y, m.dir, m.carrying)
}

/// `(end_x, end_y, end_dir, end_carrying)`: where the action left the agent.
fn end_pose(m: &EnvMeta) -> (u16, u16, u8, u8) {
    (m.end_x, m.end_y, m.end_dir, m.end_carrying)
}

/// A batch of `n` on `text`, reset, its final cells marked unwritten.
fn batch(text: &str, cfg: EnvConfig, n: usize) -> (BatchEnv, StepBuffers) {
    let layout = Layout::parse("test", text).expect("valid layout");
    let mut b = BatchEnv::new(layout, cfg, n, 7, 1).unwrap();
    let mut buf = b.buffers();
    b.reset(buf.out());
    buf.final_cells.fill(UNWRITTEN);
    (b, buf)
}

/// Environment `i`'s block of `cells`.
fn block(cells: &[u8], i: usize, cpe: usize) -> &[u8] {
    &cells[i * cpe..(i + 1) * cpe]
}

#[test]
fn walking_onto_the_exit_reports_the_exit_as_end_pose_and_the_grid_it_ended_on() {
    // Env 0 walks right over both balls onto the exit; env 1 turns in place.
    let text = "#######\n#>B.BE#\n#######\n";
    let (mut b, mut buf) = batch(text, config(Task::MultiGoal, 100), 2);
    let (w, cpe) = (b.layout().width, b.cells_per_env());
    let (start, exit) = (w + 1, w + 5);
    for t in 0..3 {
        b.step(&[FORWARD, LEFT], buf.out());
        for m in &buf.meta {
            assert!(!m.done(), "step {t}");
            assert_eq!(end_pose(m), pose(m), "step {t}: nothing ended");
        }
        assert!(
            buf.final_cells.iter().all(|&c| c == UNWRITTEN),
            "step {t}: no final cells without an ending episode"
        );
    }
    assert_eq!(buf.meta[0].cell(w), exit - 1);

    b.step(&[FORWARD, LEFT], buf.out());
    let m = buf.meta[0];
    assert_eq!(m.flags, flags::TERMINATED | flags::RESET);
    assert!((m.reward - 0.99).abs() < 1e-5, "{}", m.reward);
    assert_eq!((m.balls, m.episode_len), (2, 4));
    assert_eq!(
        end_pose(&m),
        (5, 1, 0, EnvMeta::CARRYING_NOTHING),
        "the action led onto the exit"
    );
    assert_eq!(m.end_cell(w), exit);
    assert_eq!(
        (m.x, m.y, m.dir),
        (1, 1, 0),
        "the observation is the next episode's start"
    );
    assert_eq!(m.cell(w), start);
    let finals = block(&buf.final_cells, 0, cpe);
    let cells = block(&buf.cells, 0, cpe);
    assert_eq!(
        finals[w + 2],
        Object::Floor as u8,
        "the first ball was collected"
    );
    assert_eq!(
        finals[w + 4],
        Object::Floor as u8,
        "the second ball was collected"
    );
    assert_eq!(finals[exit], Object::Exit as u8);
    assert_eq!(
        cells,
        &b.layout().cells[..],
        "the new episode has both balls"
    );
    assert_ne!(finals, cells);
    // Env 1 did not finish: same pose both ways, its final cells untouched.
    assert!(!buf.meta[1].done());
    assert_eq!(end_pose(&buf.meta[1]), pose(&buf.meta[1]));
    assert!(
        block(&buf.final_cells, 1, cpe)
            .iter()
            .all(|&c| c == UNWRITTEN)
    );

    // The next step starts from the new episode: nothing ended, and the
    // finished episode's final cells stay as they were.
    b.step(&[LEFT, LEFT], buf.out());
    assert!(buf.meta.iter().all(|m| !m.done() && end_pose(m) == pose(m)));
    assert_eq!(buf.meta[0].cell(w), start);
    assert_eq!(block(&buf.final_cells, 0, cpe)[w + 2], Object::Floor as u8);
}

#[test]
fn the_end_pose_holds_what_the_agent_carried_when_the_episode_ended() {
    // Pick up the key, unlock the door, walk through onto the exit.
    let text = "######\n#>KDE#\n######\n";
    let (mut b, mut buf) = batch(text, config(Task::DoorKey, 100), 1);
    let w = b.layout().width;
    for a in [PICKUP, FORWARD, TOGGLE, FORWARD] {
        b.step(&[a], buf.out());
        let m = buf.meta[0];
        assert!(!m.done());
        assert_eq!(end_pose(&m), pose(&m));
    }
    assert_eq!(buf.meta[0].carrying, Object::Key as u8);
    b.step(&[FORWARD], buf.out());
    let m = buf.meta[0];
    assert!(m.terminated() && m.flags & flags::RESET != 0);
    assert_eq!(end_pose(&m), (4, 1, 0, Object::Key as u8));
    assert_eq!(pose(&m), (1, 1, 0, EnvMeta::CARRYING_NOTHING));
    assert_eq!(
        (buf.final_cells[w + 2], buf.final_cells[w + 3]),
        (Object::Floor as u8, Object::DoorOpen as u8),
        "the episode ended with the key taken and the door open"
    );
    assert_eq!(
        (buf.cells[w + 2], buf.cells[w + 3]),
        (Object::Key as u8, Object::DoorLocked as u8),
        "the next episode starts with both back"
    );
}

/// Environment `i` of a batch with auto-reset off, reset as
/// [`BatchEnv::reset`] resets the batch: it stays on the final state the
/// same-step environment reports beside its next observation.
fn twin(layout: &Layout, cfg: EnvConfig, seed: u64, i: usize) -> Env {
    let cfg = EnvConfig {
        auto_reset: AutoReset::Off,
        ..cfg
    };
    let mut env = Env::new(layout.clone(), cfg, seed, i as u64);
    let (mut cells, mut meta) = (vec![0; layout.cells.len()], EnvMeta::EMPTY);
    env.reset(&mut cells, &mut meta);
    env
}

/// Steps `b` and the auto-reset-off `twins` of its environments with the
/// same actions and checks every record: on a step that ended nothing the
/// two agree, on an ending step the end pose and final cells are the
/// twin's state before its reset, and the observation the twin's reset.
/// Returns the ending steps seen, `(terminated, truncated)`.
fn step_against_twins(
    b: &mut BatchEnv,
    buf: &mut StepBuffers,
    twins: &mut [Env],
    actions: &[u8],
) -> (usize, usize) {
    let cpe = b.cells_per_env();
    let before = buf.final_cells.clone();
    b.step(actions, buf.out());
    let (mut terminated, mut truncated) = (0, 0);
    for (i, t) in twins.iter_mut().enumerate() {
        let (mut cells, mut finals, mut tm) = (vec![0; cpe], vec![UNWRITTEN; cpe], EnvMeta::EMPTY);
        t.step(actions[i], &mut cells, &mut finals, &mut tm);
        let m = buf.meta[i];
        assert_eq!(
            end_pose(&tm),
            pose(&tm),
            "auto-reset off: end = observation"
        );
        if !m.done() {
            assert!(!tm.done());
            assert_eq!(m, tm, "env {i}: a step that ended nothing");
            assert_eq!(block(&buf.cells, i, cpe), &cells[..]);
            assert_eq!(
                block(&buf.final_cells, i, cpe),
                block(&before, i, cpe),
                "env {i}: final cells untouched"
            );
            continue;
        }
        terminated += usize::from(m.terminated());
        truncated += usize::from(m.truncated());
        assert_eq!(m.flags, tm.flags | flags::RESET, "env {i}");
        assert_eq!(
            (m.reward, m.episode_return, m.episode_len, m.balls),
            (tm.reward, tm.episode_return, tm.episode_len, tm.balls)
        );
        assert_eq!(end_pose(&m), pose(&tm), "env {i}: the final pose");
        assert_eq!(m.end_cell(b.layout().width), t.cell());
        assert_eq!(
            block(&buf.final_cells, i, cpe),
            t.grid(),
            "env {i}: the final grid"
        );
        assert_eq!(
            &finals[..],
            t.grid(),
            "a single env writes its final cells too"
        );
        // The twin's reset is the same-step environment's new episode.
        t.reset(&mut cells, &mut tm);
        assert_eq!(pose(&m), pose(&tm), "env {i}: the next episode's start");
        assert_eq!(block(&buf.cells, i, cpe), &cells[..]);
    }
    (terminated, truncated)
}

#[test]
fn a_truncated_step_reports_the_final_pose_and_grid_on_the_small_maze() {
    let layout = Maze::Small.layout(false);
    let cfg = EnvConfig {
        max_steps: 7,
        ..EnvConfig::for_task(Task::MultiGoal, &layout)
    };
    assert!(matches!(cfg.balls, BallSpawn::Random(5)));
    let (n, seed) = (6, 11);
    let mut b = BatchEnv::new(layout.clone(), cfg, n, seed, 1).unwrap();
    let mut twins: Vec<Env> = (0..n).map(|i| twin(&layout, cfg, seed, i)).collect();
    let mut buf = b.buffers();
    b.reset(buf.out());
    buf.final_cells.fill(UNWRITTEN);
    let cpe = b.cells_per_env();
    let mut truncations = 0;
    for t in 0..29 {
        // Mostly forward, with turns: the agents wander off the start.
        let actions: Vec<u8> = (0..n)
            .map(|i| [FORWARD, FORWARD, RIGHT, FORWARD, LEFT][(t * 3 + i * 7) % 5])
            .collect();
        let (_, tr) = step_against_twins(&mut b, &mut buf, &mut twins, &actions);
        truncations += tr;
        for (i, m) in buf.meta.iter().enumerate().filter(|(_, m)| m.truncated()) {
            assert_ne!(
                block(&buf.final_cells, i, cpe),
                block(&buf.cells, i, cpe),
                "env {i}: the new episode's balls are drawn anew"
            );
            assert_eq!(m.episode_len, 7);
        }
    }
    assert_eq!(
        truncations,
        4 * n,
        "every env truncated at steps 7, 14, 21, 28"
    );
}

/// The shortest walk from the start to the exit as actions (breadth-first
/// over cells the agent can enter; balls are collected on the way).
fn walk_to_exit(layout: &Layout) -> Vec<u8> {
    let w = layout.width;
    let offset = [1isize, w as isize, -1, -(w as isize)];
    let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize);
    let passable = |c: u8| c != Object::Wall as u8;
    let mut from = vec![usize::MAX; layout.cells.len()];
    from[start] = start;
    let mut queue = VecDeque::from([start]);
    let mut exit = None;
    while let Some(c) = queue.pop_front() {
        if layout.cells[c] == Object::Exit as u8 {
            exit = Some(c);
            break;
        }
        for o in offset {
            let n = (c as isize + o) as usize;
            if passable(layout.cells[n]) && from[n] == usize::MAX {
                from[n] = c;
                queue.push_back(n);
            }
        }
    }
    let mut path = vec![exit.expect("the exit is reachable")];
    while *path.last().unwrap() != start {
        path.push(from[*path.last().unwrap()]);
    }
    path.reverse();
    let (mut dir, mut actions) = (layout.start.dir, Vec::new());
    for step in path.windows(2) {
        let want = offset
            .iter()
            .position(|&o| (step[0] as isize + o) as usize == step[1])
            .unwrap() as u8;
        while dir != want {
            actions.push(RIGHT);
            dir = (dir + 1) & 3;
        }
        actions.push(FORWARD);
    }
    actions
}

#[test]
fn walking_the_small_maze_to_its_exit_ends_on_the_exit_and_restarts_at_the_start() {
    let layout = Maze::Small.layout(false);
    assert!(
        layout
            .cells
            .iter()
            .all(|&c| c != Object::DoorClosed as u8 && c != Object::DoorLocked as u8)
    );
    let cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
    let walk = walk_to_exit(&layout);
    assert!((walk.len() as u32) < cfg.max_steps);
    let (n, seed) = (3, 5);
    let mut b = BatchEnv::new(layout.clone(), cfg, n, seed, 1).unwrap();
    let mut twins: Vec<Env> = (0..n).map(|i| twin(&layout, cfg, seed, i)).collect();
    let mut buf = b.buffers();
    b.reset(buf.out());
    buf.final_cells.fill(UNWRITTEN);
    let w = layout.width;
    let exit = layout
        .cells
        .iter()
        .position(|&c| c == Object::Exit as u8)
        .unwrap();
    let start = layout.cell_index(layout.start.x as usize, layout.start.y as usize);
    for (t, &a) in walk.iter().enumerate() {
        // Env 0 walks to the exit, env 1 turns in place, env 2 waits.
        let (terminated, truncated) =
            step_against_twins(&mut b, &mut buf, &mut twins, &[a, LEFT, DONE]);
        assert_eq!(truncated, 0);
        assert_eq!(terminated, usize::from(t + 1 == walk.len()), "step {t}");
    }
    let m = buf.meta[0];
    assert!(m.terminated() && m.flags & flags::RESET != 0);
    assert_eq!(m.end_cell(w), exit, "the last step is judged at the exit");
    assert_eq!(
        m.cell(w),
        start,
        "while the observation is back at the start"
    );
    let cpe = b.cells_per_env();
    assert_eq!(block(&buf.final_cells, 0, cpe)[exit], Object::Exit as u8);
    assert_ne!(
        block(&buf.final_cells, 0, cpe),
        block(&buf.cells, 0, cpe),
        "the finished episode's balls are not the new one's"
    );
    for i in 1..n {
        assert!(
            block(&buf.final_cells, i, cpe)
                .iter()
                .all(|&c| c == UNWRITTEN)
        );
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig {
        cases: 48,
        failure_persistence: None,
        ..proptest::prelude::ProptestConfig::default()
    })]

    /// Every task on the small and medium mazes, random actions, short
    /// episodes: the same-step environment's end pose and final cells are
    /// the state its auto-reset-off twin ends on.
    #[test]
    fn same_step_auto_reset_reports_the_state_auto_reset_off_ends_on(
        task in proptest::sample::select(Task::ALL.to_vec()),
        maze in proptest::sample::select(vec![Maze::Small, Maze::Medium]),
        max_steps in 3u32..40,
        seed in proptest::prelude::any::<u64>(),
        actions in proptest::collection::vec(0u8..7, 1..150),
    ) {
        let layout = maze.layout(task.uses_door_key_layout());
        let cfg = EnvConfig { max_steps, ..EnvConfig::for_task(task, &layout) };
        let n = 4;
        let mut b = BatchEnv::new(layout.clone(), cfg, n, seed, 1).unwrap();
        let mut twins: Vec<Env> = (0..n).map(|i| twin(&layout, cfg, seed, i)).collect();
        let mut buf = b.buffers();
        b.reset(buf.out());
        let mut ended = 0;
        for (t, &a) in actions.iter().enumerate() {
            let acts: Vec<u8> = (0..n).map(|i| (a as usize + i * 3 + t) as u8 % 7).collect();
            let (te, tr) = step_against_twins(&mut b, &mut buf, &mut twins, &acts);
            ended += te + tr;
        }
        proptest::prop_assert!(actions.len() < max_steps as usize || ended >= n);
    }
}
