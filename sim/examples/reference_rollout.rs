//! The reference the Python package is checked against
//! (python/tests/test_differential.py): `N` environments stepped one by one
//! through `sim::Env` directly — no `BatchEnv`, no threads, no NumPy — on
//! the actions of a file, writing every observation and step record.
//!
//! ```text
//! reference_rollout TASK MAZE|@LAYOUT_FILE SEED N MAX_STEPS ACTIONS_FILE OUT_FILE
//! ```
//! `ACTIONS_FILE`: `T × N` bytes, step-major. `OUT_FILE`: the reset's
//! observation, then per step and environment (step-major) one record:
//! the grid (`H·W` bytes), the final grid when the step ended the episode
//! (`H·W` bytes, zero otherwise) and the step record as 28 little-endian
//! bytes: reward f32, episode_return f32, episode_len u32, x u16, y u16,
//! dir u8, carrying u8, flags u8, balls u8, end_x u16, end_y u16, end_dir
//! u8, end_carrying u8, reserved u16. `MAX_STEPS` 0 keeps the task's
//! default; `make test` builds this example before the Python tests.

use std::io::Write;

use sim::{AutoReset, Env, EnvConfig, EnvMeta, Layout, Maze, Task};

fn record(out: &mut Vec<u8>, cells: &[u8], finals: &[u8], m: &EnvMeta) {
    out.extend_from_slice(cells);
    out.extend_from_slice(finals);
    out.extend_from_slice(&m.reward.to_le_bytes());
    out.extend_from_slice(&m.episode_return.to_le_bytes());
    out.extend_from_slice(&m.episode_len.to_le_bytes());
    out.extend_from_slice(&m.x.to_le_bytes());
    out.extend_from_slice(&m.y.to_le_bytes());
    out.extend_from_slice(&[m.dir, m.carrying, m.flags, m.balls]);
    out.extend_from_slice(&m.end_x.to_le_bytes());
    out.extend_from_slice(&m.end_y.to_le_bytes());
    out.extend_from_slice(&[m.end_dir, m.end_carrying]);
    out.extend_from_slice(&m.reserved.to_le_bytes());
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [task, maze, seed, n, max_steps, actions, out] = args.as_slice() else {
        return Err("usage: reference_rollout TASK MAZE|@LAYOUT_FILE SEED N MAX_STEPS ACTIONS_FILE OUT_FILE".into());
    };
    let task: Task = task.parse()?;
    let layout = match maze.strip_prefix('@') {
        Some(path) => Layout::from_file(std::path::Path::new(path))?,
        None => Maze::ALL
            .into_iter()
            .find(|m| m.name() == maze)
            .ok_or("unknown maze")?
            .layout(task.uses_door_key_layout()),
    };
    let (seed, n, max_steps): (u64, usize, u32) = (seed.parse()?, n.parse()?, max_steps.parse()?);
    let mut cfg = EnvConfig::for_task(task, &layout);
    if max_steps > 0 {
        cfg.max_steps = max_steps;
    }
    cfg.auto_reset = AutoReset::SameStep;
    let actions = std::fs::read(actions)?;
    if n == 0 || actions.len() % n != 0 {
        return Err("the actions file is not T × N bytes".into());
    }
    let hw = layout.width * layout.height;
    let mut envs: Vec<Env> = (0..n)
        .map(|i| Env::new(layout.clone(), cfg, seed, i as u64))
        .collect();
    let (mut cells, mut finals, mut meta) = (vec![0u8; hw], vec![0u8; hw], EnvMeta::EMPTY);
    let zeros = vec![0u8; hw];
    let mut buf = Vec::new();
    for env in &mut envs {
        env.reset(&mut cells, &mut meta);
        record(&mut buf, &cells, &zeros, &meta);
    }
    for step in actions.chunks(n) {
        for (env, &a) in envs.iter_mut().zip(step) {
            env.step(a, &mut cells, &mut finals, &mut meta);
            let f = if meta.done() { &finals[..] } else { &zeros[..] };
            record(&mut buf, &cells, f, &meta);
        }
    }
    std::fs::File::create(out)?.write_all(&buf)?;
    Ok(())
}
