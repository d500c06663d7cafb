//! `worldgraph sim render|trace`.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use serde_json::json;
use sim::{AutoReset, BatchEnv, Env, EnvMeta, Object, action, render};

use crate::world_args::WorldArgs;

/// Simulator tools.
#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Print a maze's first observation as ASCII and optionally write a PNG.
    Render(RenderArgs),
    /// Run one environment on a given action sequence and print each step.
    Trace(TraceArgs),
    /// The sim process of the pipeline: step the batch on each action batch
    /// and publish observations through shared memory.
    Serve(crate::roles::sim::SimServeArgs),
}

/// `sim render` options.
#[derive(Debug, Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    /// Write a PNG of the observation (or of a batch grid with --batch).
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Render this many environments of a batch (seeds (seed, 0..N)) as a grid.
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Pixels per cell in the PNG.
    #[arg(long, default_value_t = 16)]
    pub cell_px: usize,
}

/// `sim trace` options.
#[derive(Debug, Args)]
pub struct TraceArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    /// Comma-separated actions, as MiniGrid codes (0 left, 1 right, 2
    /// forward, 3 pickup, 4 drop, 5 toggle, 6 done) or names ("forward").
    #[arg(long, value_delimiter = ',', required = true)]
    pub actions: Vec<String>,
    /// One JSON object per line (the default output is a readable table).
    #[arg(long)]
    pub json: bool,
}

/// Runs a `sim` subcommand.
pub fn run(cmd: SimCommand) -> anyhow::Result<std::process::ExitCode> {
    match cmd {
        SimCommand::Render(a) => render_cmd(a),
        SimCommand::Trace(a) => trace_cmd(a),
        SimCommand::Serve(a) => return crate::roles::sim::serve(a),
    }
    .map(|()| std::process::ExitCode::SUCCESS)
}

fn render_cmd(a: RenderArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.batch >= 1, "--batch must be at least 1");
    anyhow::ensure!((2..=64).contains(&a.cell_px), "--cell-px must be in 2..=64");
    if let Some(path) = &a.png {
        crate::picture_path::prepare("--png", path)?;
    }
    let (layout, cfg) = a.world.build()?;
    let (w, h) = (layout.width, layout.height);
    let mut batch = BatchEnv::new(layout, cfg, a.batch, a.world.seed, 1)?;
    let mut buf = batch.buffers();
    batch.reset(buf.out());
    print!("{}", render::ascii(&buf.cells[..w * h], w, &buf.meta[0]));
    println!(
        "{} maze {}x{}, task {}, seed {}, step limit {}",
        batch.layout().name,
        w,
        h,
        cfg.task,
        a.world.seed,
        cfg.max_steps
    );
    if let Some(path) = &a.png {
        let canvas = if a.batch == 1 {
            render::render_env(&buf.cells, w, h, &buf.meta[0], a.cell_px)
        } else {
            let cols = (a.batch as f64).sqrt().ceil() as usize;
            render::render_batch(&buf.cells, &buf.meta, w, h, a.batch, cols, a.cell_px)
        };
        canvas.save_png(path)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Parses one action: a MiniGrid code or a name.
fn parse_action(s: &str) -> anyhow::Result<u8> {
    let s = s.trim();
    if let Ok(n) = s.parse::<u8>() {
        anyhow::ensure!(n <= 6, "action {n} out of range 0..=6");
        return Ok(n);
    }
    action::NAMES
        .iter()
        .position(|&name| name.eq_ignore_ascii_case(s))
        .map(|i| i as u8)
        .with_context(|| {
            format!(
                "unknown action {s:?}: use 0..=6 or one of {:?}",
                action::NAMES
            )
        })
}

fn step_json(t: usize, act: Option<u8>, env: &Env, m: &EnvMeta) -> serde_json::Value {
    let doors: Vec<_> = env
        .doors()
        .into_iter()
        .map(|(x, y, o)| {
            let state = match o {
                Object::DoorOpen => "open",
                Object::DoorClosed => "closed",
                _ => "locked",
            };
            json!({ "pos": [x, y], "state": state })
        })
        .collect();
    json!({
        "t": t,
        "action": act.map(|a| action::NAMES[a as usize]),
        "pos": [m.x, m.y],
        "dir": m.dir,
        "carrying": Object::from_code(m.carrying).map(Object::name),
        "reward": (m.reward * 1e4).round() / 1e4,
        "terminated": m.terminated(),
        "truncated": m.truncated(),
        "episode_return": (m.episode_return * 1e4).round() / 1e4,
        "balls": m.balls,
        "doors": doors,
    })
}

fn trace_cmd(a: TraceArgs) -> anyhow::Result<()> {
    let actions: Vec<u8> = a
        .actions
        .iter()
        .map(|s| parse_action(s))
        .collect::<anyhow::Result<_>>()?;
    let (layout, mut cfg) = a.world.build()?;
    cfg.auto_reset = AutoReset::Off;
    let cells = layout.width * layout.height;
    let mut env = Env::new(layout, cfg, a.world.seed, 0);
    let mut grid = vec![0u8; cells];
    let mut meta = EnvMeta::EMPTY;
    env.reset(&mut grid, &mut meta);
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut emit = |t: usize, act: Option<u8>, env: &Env, m: &EnvMeta| -> std::io::Result<()> {
        if a.json {
            writeln!(out, "{}", step_json(t, act, env, m))
        } else {
            writeln!(
                out,
                "t={t:<4} {:<8} pos=({:>2},{:>2}) dir={} carrying={:<6} reward={:+.2} return={:+.2}{}{}",
                act.map_or("-", |a| action::NAMES[a as usize]),
                m.x,
                m.y,
                m.dir,
                Object::from_code(m.carrying).map_or("-", Object::name),
                m.reward,
                m.episode_return,
                if m.terminated() { " TERMINATED" } else { "" },
                if m.truncated() { " TRUNCATED" } else { "" },
            )
        }
    };
    emit(0, None, &env, &meta)?;
    for (t, &act) in actions.iter().enumerate() {
        let m = env.step_meta(act);
        emit(t + 1, Some(act), &env, &m)?;
    }
    Ok(())
}
