//! Invariants of the simulator, checked on random layouts and action streams.

use proptest::prelude::*;
use sim::{AutoReset, BatchEnv, Env, EnvConfig, EnvMeta, Layout, Maze, Object, Task, flags};

/// A random enclosed layout: walls scattered inside, a start and an exit.
fn layout_strategy() -> impl Strategy<Value = Layout> {
    (5usize..12, 5usize..12, any::<u64>()).prop_filter_map("exit reachable", |(w, h, seed)| {
        let mut rng = seed;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let mut text = String::new();
        let inner: Vec<(usize, usize)> = (1..h - 1)
            .flat_map(|y| (1..w - 1).map(move |x| (x, y)))
            .collect();
        let start = inner[(next() % inner.len() as u64) as usize];
        let exit = inner[(next() % inner.len() as u64) as usize];
        if start == exit {
            return None;
        }
        for y in 0..h {
            for x in 0..w {
                let c = if x == 0 || y == 0 || x == w - 1 || y == h - 1 {
                    '#'
                } else if (x, y) == start {
                    ['>', 'v', '<', '^'][(next() % 4) as usize]
                } else if (x, y) == exit {
                    'E'
                } else {
                    match next() % 10 {
                        0 | 1 => '#',
                        2 => 'C',
                        3 => 'K',
                        _ => '.',
                    }
                };
                text.push(c);
            }
            text.push('\n');
        }
        Layout::parse("random", &text).ok()
    })
}

fn task_strategy() -> impl Strategy<Value = Task> {
    prop::sample::select(Task::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn the_agent_never_enters_a_wall(layout in layout_strategy(), task in task_strategy(),
                                     actions in prop::collection::vec(0u8..7, 1..300), seed in any::<u64>()) {
        let cfg = EnvConfig { task, max_steps: 1000, ..EnvConfig::for_task(task, &layout) };
        let mut env = Env::new(layout.clone(), cfg, seed, 0);
        for a in actions {
            let m = env.step_meta(a);
            let cell = env.grid()[m.y as usize * layout.width + m.x as usize];
            prop_assert_ne!(cell, Object::Wall as u8);
            prop_assert!(cell != Object::DoorLocked as u8 && cell != Object::DoorClosed as u8);
        }
    }

    #[test]
    fn a_batch_of_n_equals_n_single_environments(task in task_strategy(), n in 1usize..40, seed in any::<u64>(),
                                                 actions in prop::collection::vec(0u8..7, 1..60)) {
        let layout = Maze::Small.layout(task.uses_door_key_layout());
        let cfg = EnvConfig { max_steps: 25, ..EnvConfig::for_task(task, &layout) };
        let mut batch = BatchEnv::new(layout.clone(), cfg, n, seed, 2).unwrap();
        let mut singles: Vec<Env> = (0..n as u64).map(|i| Env::new(layout.clone(), cfg, seed, i)).collect();
        let mut buf = batch.buffers();
        let cpe = batch.cells_per_env();
        batch.reset(buf.out());
        for (i, env) in singles.iter_mut().enumerate() {
            let (mut cells, mut meta) = (vec![0u8; cpe], EnvMeta::EMPTY);
            env.reset(&mut cells, &mut meta);
            prop_assert_eq!(&buf.cells[i * cpe..(i + 1) * cpe], &cells[..]);
            prop_assert_eq!(buf.meta[i], meta);
        }
        for (t, &a) in actions.iter().enumerate() {
            let acts: Vec<u8> = (0..n).map(|i| (a as usize + i * 3 + t) as u8 % 7).collect();
            batch.step(&acts, buf.out());
            for (i, env) in singles.iter_mut().enumerate() {
                let (mut cells, mut finals) = (vec![0u8; cpe], vec![0u8; cpe]);
                let mut meta = EnvMeta::EMPTY;
                env.step(acts[i], &mut cells, &mut finals, &mut meta);
                prop_assert_eq!(&buf.cells[i * cpe..(i + 1) * cpe], &cells[..]);
                prop_assert_eq!(buf.meta[i], meta);
                if meta.done() {
                    prop_assert_eq!(&buf.final_cells[i * cpe..(i + 1) * cpe], &finals[..]);
                }
            }
        }
    }

    #[test]
    fn same_seed_same_trajectory_on_one_and_two_threads(task in task_strategy(), seed in any::<u64>(),
                                                        actions in prop::collection::vec(0u8..7, 1..80)) {
        let layout = Maze::Medium.layout(task.uses_door_key_layout());
        let cfg = EnvConfig { max_steps: 30, auto_reset: AutoReset::SameStep, ..EnvConfig::for_task(task, &layout) };
        let n = 64;
        let mut one = BatchEnv::new(layout.clone(), cfg, n, seed, 1).unwrap();
        let mut two = BatchEnv::new(layout, cfg, n, seed, 2).unwrap();
        let (mut b1, mut b2) = (one.buffers(), two.buffers());
        one.reset(b1.out());
        two.reset(b2.out());
        let mut ends = 0;
        for &a in &actions {
            let acts: Vec<u8> = (0..n).map(|i| (a as usize + i) as u8 % 7).collect();
            one.step(&acts, b1.out());
            two.step(&acts, b2.out());
            prop_assert_eq!(&b1.cells, &b2.cells);
            prop_assert_eq!(&b1.meta, &b2.meta);
            prop_assert_eq!(&b1.final_cells, &b2.final_cells);
            ends += b1.meta.iter().filter(|m| m.flags & flags::DONE != 0).count();
        }
        prop_assert!(actions.len() < 30 || ends > 0, "episodes ended and reset along the way");
    }
}

/// The pipeline publishes a batch in slices (`BatchEnv::with_first_index`):
/// stepping the slices one after the other gives the whole batch's
/// observations, byte for byte.
#[test]
fn a_batch_stepped_in_slices_equals_the_whole_batch() {
    let layout = Maze::Medium.layout(false);
    let cfg = EnvConfig::for_task(Task::MultiGoalStochastic, &layout);
    let (n, k, seed) = (24, 3, 7);
    let mut whole = BatchEnv::new(layout.clone(), cfg, n, seed, 1).unwrap();
    let mut parts: Vec<BatchEnv> = (0..k)
        .map(|s| {
            BatchEnv::with_first_index(layout.clone(), cfg, s * n / k, n / k, seed, 1).unwrap()
        })
        .collect();
    let mut a = whole.buffers();
    let mut b = whole.buffers();
    let cpe = whole.cells_per_env();
    let per = n / k;
    let split = |b: &mut sim::StepBuffers, s: usize| -> (Vec<u8>, Vec<EnvMeta>) {
        (
            b.cells[s * per * cpe..(s + 1) * per * cpe].to_vec(),
            b.meta[s * per..(s + 1) * per].to_vec(),
        )
    };
    whole.reset(a.out());
    for (s, part) in parts.iter_mut().enumerate() {
        let (mut cells, mut meta) = split(&mut b, s);
        let mut finals = vec![0u8; cells.len()];
        part.reset(sim::StepOut {
            cells: &mut cells,
            final_cells: &mut finals,
            meta: &mut meta,
        });
        b.cells[s * per * cpe..(s + 1) * per * cpe].copy_from_slice(&cells);
        b.meta[s * per..(s + 1) * per].copy_from_slice(&meta);
    }
    assert_eq!(a.cells, b.cells);
    for t in 0..300u32 {
        let actions: Vec<u8> = (0..n as u32)
            .map(|i| ((i * 7 + t * 13) % 3) as u8)
            .collect();
        whole.step(&actions, a.out());
        for (s, part) in parts.iter_mut().enumerate() {
            let (mut cells, mut meta) = split(&mut b, s);
            let mut finals = b.final_cells[s * per * cpe..(s + 1) * per * cpe].to_vec();
            part.step(
                &actions[s * per..(s + 1) * per],
                sim::StepOut {
                    cells: &mut cells,
                    final_cells: &mut finals,
                    meta: &mut meta,
                },
            );
            b.final_cells[s * per * cpe..(s + 1) * per * cpe].copy_from_slice(&finals);
            b.cells[s * per * cpe..(s + 1) * per * cpe].copy_from_slice(&cells);
            b.meta[s * per..(s + 1) * per].copy_from_slice(&meta);
        }
        assert_eq!(a.cells, b.cells, "cells differ at step {t}");
        assert_eq!(a.meta, b.meta, "metas differ at step {t}");
        assert_eq!(
            a.final_cells, b.final_cells,
            "final cells differ at step {t}"
        );
    }
}
