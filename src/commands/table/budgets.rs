//! The budget sections of the README `table` writes: what each maze's runs
//! were given (env steps, how often they were validated, their share of the
//! paper's budget) and what each cell cost in wall seconds.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use crate::results::RunResult;

use super::Cells;
use super::display_config;
use super::paper::{PAPER_ITERATIONS, TABLE1_CONFIGS, TASKS};

/// The "Budgets" section: per maze of `mazes`, the env steps its runs
/// trained, how often they were validated, their mean wall time and speed
/// and their share of the paper's budget; then how that budget is taken.
pub(super) fn section(runs: &[RunResult], mazes: &[&str]) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "## Budgets\n");
    let _ = writeln!(
        md,
        "| maze | env steps per run (trained) | validation every | runs | mean wall s per run | mean training env-steps/s | share of the paper's budget |\n|---|---:|---:|---:|---:|---:|---:|"
    );
    for m in mazes {
        let rs: Vec<&RunResult> = runs.iter().filter(|r| r.maze == *m).collect();
        let steps: BTreeSet<u64> = rs.iter().map(|r| r.env_steps).collect();
        let every: BTreeSet<u64> = rs.iter().map(|r| r.train_config.eval_every).collect();
        let wall = rs.iter().map(|r| r.wall_seconds).sum::<f64>() / rs.len() as f64;
        let sps = rs.iter().map(|r| r.train_steps_per_sec).sum::<f64>() / rs.len() as f64;
        let paper_steps = paper_budget(rs[0]);
        let _ = writeln!(
            md,
            "| {m} | {} | {} | {} | {wall:.0} | {sps:.0} | {:.3} % |",
            join(&steps),
            join(&every),
            rs.len(),
            100.0 * *steps.iter().max().expect("runs") as f64 / paper_steps as f64
        );
    }
    let _ = writeln!(
        md,
        "\nThe paper's budget is taken as 100k iterations × {} agents × a rollout of {} steps \
         (this repository's rollout; the paper's main text does not state its own). Wall times \
         are on the 2-core machine with `jobs` runs side by side (each summary records it).\n",
        runs[0].train_config.agent.envs, runs[0].train_config.agent.rollout_len
    );
    md
}

/// The "Budget per cell" section: the mean training wall seconds per run
/// of every cell (training env-steps/s in brackets), a row per
/// configuration of Table 1, a column per task and maze that ran.
pub(super) fn per_cell(runs: &[RunResult], cells: &Cells, mazes: &[&str]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## Budget per cell\n\nMean training wall seconds per run (env steps per run: the budgets \
         above; training env-steps/s in brackets).\n"
    );
    let tasks_here: Vec<&str> = TASKS
        .iter()
        .copied()
        .filter(|t| runs.iter().any(|r| r.task == *t))
        .collect();
    let mut head = "| configuration |".to_string();
    let mut rule = "|---|".to_string();
    for t in &tasks_here {
        for m in mazes {
            let _ = write!(head, " {t}, {m} |");
            rule.push_str("---:|");
        }
    }
    let _ = writeln!(md, "{head}\n{rule}");
    for c in TABLE1_CONFIGS {
        let mut line = format!("| {} |", display_config(c));
        for t in &tasks_here {
            for m in mazes {
                let k = (m.to_string(), t.to_string(), c.to_string());
                let text = match cells.get(&k) {
                    Some(rs) if !rs.is_empty() => {
                        let n = rs.len() as f64;
                        format!(
                            "{:.0} ({:.0})",
                            rs.iter().map(|r| r.wall_seconds).sum::<f64>() / n,
                            rs.iter().map(|r| r.train_steps_per_sec).sum::<f64>() / n
                        )
                    }
                    _ => "—".to_string(),
                };
                let _ = write!(line, " {text} |");
            }
        }
        let _ = writeln!(md, "{line}");
    }
    let _ = writeln!(md);
    md
}

/// The paper's budget in env steps at `r`'s agent shape: 100k iterations
/// × its envs × its rollout.
fn paper_budget(r: &RunResult) -> u64 {
    PAPER_ITERATIONS * (r.train_config.agent.envs * r.train_config.agent.rollout_len) as u64
}

/// A maze's column or row label with the budget of its runs beside it and
/// that budget's share of the paper's: `small (3024000 env steps, 1.575 %
/// of the paper's)`, as in the budgets table.
pub(super) fn budget_label(runs: &[RunResult], maze: &str) -> String {
    let Some(steps) = runs
        .iter()
        .filter(|r| r.maze == maze)
        .map(|r| r.env_steps)
        .max()
    else {
        return maze.to_string();
    };
    let r = runs
        .iter()
        .find(|r| r.maze == maze)
        .expect("a run of the maze");
    let paper = paper_budget(r);
    format!(
        "{maze} ({steps} env steps, {:.3} % of the paper's)",
        100.0 * steps as f64 / paper as f64
    )
}

fn join(xs: &BTreeSet<u64>) -> String {
    xs.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}
