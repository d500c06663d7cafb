//! `table`'s aggregate section and `scores.csv`: the run summaries reported
//! the way deep RL reports results today (the `rliable` protocol, Agarwal
//! et al. 2021; the statistics are in [`crate::stats`]).
//!
//! - Per maze and task, every configuration's interquartile mean of the test
//!   scores over its seeds with a stratified bootstrap 95 % interval.
//! - The probability of improvement of `V_p` over `V_rand`, of WN over FN,
//!   of `π_g` initialisation, of traversal and of every hierarchy over A2C,
//!   each pooled over the mazes and tasks where both configurations ran (one
//!   stratum per maze and task), with its interval; then the same per maze
//!   and task, since an ordering that holds on one task and fails on
//!   another averages to a coin flip.
//! - `scores.csv`: one row per run, tidy, so that pandas reads it as it is
//!   and `rliable` takes a score matrix from a pivot of it.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::results::RunResult;
use crate::stats::{BOOTSTRAP_REPS, BOOTSTRAP_SEED, Estimate, improvement_interval, iqm_interval};

/// Confidence level of every interval.
pub const LEVEL: f64 = 0.95;

/// Test scores per (maze, task, configuration), one per seed (Door-Key as a
/// success rate in [0, 1], as the summaries hold it).
type Scores = BTreeMap<(String, String, String), Vec<f64>>;

fn scores_of(runs: &[RunResult]) -> Scores {
    let mut s = Scores::new();
    for r in runs {
        s.entry((r.maze.clone(), r.task.clone(), r.config.clone()))
            .or_default()
            .push(r.test_score);
    }
    s
}

/// The comparisons of the probability of improvement: (X, Y, what it
/// asks), X and Y configuration names of the grids.
const COMPARISONS: [(&str, &str, &str); 10] = [
    (
        "wn-pivotal-init",
        "wn-random-init",
        "V_p over V_rand (π_g init)",
    ),
    (
        "wn-pivotal-trav",
        "wn-random-trav",
        "V_p over V_rand (traversal)",
    ),
    (
        "wn-pivotal-trav-init",
        "wn-random-trav-init",
        "V_p over V_rand (traversal + π_g init)",
    ),
    ("wn-all-init", "fn-init", "WN over FN (V_all, π_g init)"),
    ("wn-pivotal-init", "fn-init", "WN V_p over FN (π_g init)"),
    ("fn-init", "fn", "π_g init (FN)"),
    (
        "wn-random-trav-init",
        "wn-random-trav",
        "π_g init (WN V_rand + traversal)",
    ),
    (
        "wn-pivotal-trav-init",
        "wn-pivotal-trav",
        "π_g init (WN V_p + traversal)",
    ),
    (
        "wn-random-trav-init",
        "wn-random-init",
        "traversal (WN V_rand + π_g init)",
    ),
    (
        "wn-pivotal-trav-init",
        "wn-pivotal-init",
        "traversal (WN V_p + π_g init)",
    ),
];

/// One maze and task where both configurations of a comparison ran: its
/// maze, its task, X's scores and Y's.
type Stratum<'a> = (&'a str, &'a str, &'a [f64], &'a [f64]);

/// The strata where both `x` and `y` ran, in maze and task order.
fn paired_strata<'a>(s: &'a Scores, x: &str, y: &str) -> Vec<Stratum<'a>> {
    s.iter()
        .filter(|((_, _, c), _)| c == x)
        .filter_map(|((m, t, _), v)| {
            let w = s.get(&(m.clone(), t.clone(), y.to_string()))?;
            Some((m.as_str(), t.as_str(), v.as_slice(), w.as_slice()))
        })
        .collect()
}

/// Every comparison the section reports: [`COMPARISONS`], then each
/// hierarchy over A2C in Table 1's order.
fn comparisons(
    s: &Scores,
    display: impl Fn(&str) -> String,
    order: impl Fn(&str) -> usize,
) -> Vec<(String, String, String)> {
    let mut rows: Vec<(String, String, String)> = COMPARISONS
        .iter()
        .map(|(x, y, what)| (x.to_string(), y.to_string(), what.to_string()))
        .collect();
    // Each configuration once (a set: configurations outside Table 1 share
    // one sort key, so sorting would not bring their copies together).
    let mut hierarchies: Vec<&String> = s
        .keys()
        .map(|(_, _, c)| c)
        .filter(|c| c.as_str() != "a2c")
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    hierarchies.sort_by_key(|c| order(c));
    for c in hierarchies {
        rows.push((c.clone(), "a2c".into(), format!("{} over A2C", display(c))));
    }
    rows
}

fn interval_text(e: &Estimate, digits: usize) -> String {
    format!(
        "{:.digits$} [{:.digits$}, {:.digits$}]",
        e.point, e.lo, e.hi
    )
}

/// The Markdown section; `display` names a configuration as the paper
/// does, `order` sorts configurations (Table 1's order).
pub fn section(
    runs: &[RunResult],
    display: impl Fn(&str) -> String,
    order: impl Fn(&str) -> usize,
) -> String {
    let s = scores_of(runs);
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## Aggregate scores (the rliable protocol)\n\n\
         Interquartile mean (IQM) of the test scores over the seeds of a cell (the middle half of \
         the runs; with fewer than four runs it is their mean) with a {:.0} % stratified bootstrap \
         confidence interval ({BOOTSTRAP_REPS} resamples of the runs, seeded), and the \
         probability of improvement P(X > Y) that a run of X scores above a run of Y on the same \
         maze and task (ties count half), averaged over the mazes and tasks where both ran, then \
         per maze and task. \
         Door-Key scores are success rates in [0, 1]. Agarwal et al. 2021, \"Deep Reinforcement \
         Learning at the Edge of the Statistical Precipice\". Every run's figures are in \
         `scores.csv` beside the summaries.\n",
        LEVEL * 100.0
    );
    let mut cells: Vec<(String, String)> =
        s.keys().map(|(m, t, _)| (m.clone(), t.clone())).collect();
    cells.dedup();
    let _ = writeln!(
        md,
        "| maze | task | configuration | runs | IQM [95 % CI] |\n|---|---|---|---:|---|"
    );
    for (m, t) in &cells {
        let mut here: Vec<(&String, &Vec<f64>)> = s
            .iter()
            .filter(|((cm, ct, _), _)| cm == m && ct == t)
            .map(|((_, _, c), v)| (c, v))
            .collect();
        here.sort_by_key(|(c, _)| order(c));
        for (c, v) in here {
            let e = iqm_interval(
                std::slice::from_ref(v),
                LEVEL,
                BOOTSTRAP_REPS,
                BOOTSTRAP_SEED,
            )
            .expect("a cell has runs");
            let _ = writeln!(
                md,
                "| {m} | {t} | {} | {} | {} |",
                display(c),
                v.len(),
                interval_text(&e, 3)
            );
        }
    }
    let _ = writeln!(
        md,
        "\n### Probability of improvement\n\n\
         | X over Y | mazes × tasks | runs of X / of Y | P(X > Y) [95 % CI] |\n|---|---:|---:|---|"
    );
    let rows = comparisons(&s, &display, &order);
    let strata: Vec<Vec<Stratum>> = rows
        .iter()
        .map(|(x, y, _)| paired_strata(&s, x, y))
        .collect();
    let mut any = false;
    for ((_, _, what), here) in rows.iter().zip(&strata) {
        let xs: Vec<Vec<f64>> = here.iter().map(|(_, _, x, _)| x.to_vec()).collect();
        let ys: Vec<Vec<f64>> = here.iter().map(|(_, _, _, y)| y.to_vec()).collect();
        let Some(e) = improvement_interval(&xs, &ys, LEVEL, BOOTSTRAP_REPS, BOOTSTRAP_SEED) else {
            continue;
        };
        any = true;
        let nx: usize = xs.iter().map(Vec::len).sum();
        let ny: usize = ys.iter().map(Vec::len).sum();
        let _ = writeln!(
            md,
            "| {what} | {} | {nx} / {ny} | {} |",
            xs.len(),
            interval_text(&e, 2)
        );
    }
    if !any {
        let _ = writeln!(
            md,
            "| (no pair of configurations ran on the same maze and task) | | | |\n"
        );
        return md;
    }
    let _ = writeln!(
        md,
        "\n#### Per maze and task\n\n\
         The same comparisons on each maze and task alone (the bootstrap resamples that cell's \
         runs).\n\n\
         | X over Y | maze | task | runs of X / of Y | P(X > Y) [95 % CI] |\n|---|---|---|---:|---|"
    );
    for ((_, _, what), here) in rows.iter().zip(&strata) {
        for &(m, t, x, y) in here {
            let (xs, ys) = ([x.to_vec()], [y.to_vec()]);
            if let Some(e) = improvement_interval(&xs, &ys, LEVEL, BOOTSTRAP_REPS, BOOTSTRAP_SEED) {
                let _ = writeln!(
                    md,
                    "| {what} | {m} | {t} | {} / {} | {} |",
                    x.len(),
                    y.len(),
                    interval_text(&e, 2)
                );
            }
        }
    }
    let _ = writeln!(md);
    md
}

/// The columns of `scores.csv`, in order.
pub const SCORES_COLUMNS: [&str; 17] = [
    "maze",
    "task",
    "config",
    "seed",
    "test_score",
    "test_return",
    "test_success_rate",
    "best_validation",
    "best_env_steps",
    "env_steps",
    "eval_every",
    "paper_budget_share",
    "wall_seconds",
    "train_steps_per_sec",
    "torch_threads",
    "jobs",
    "commit",
];

/// `scores.csv`: a header and one row per run, sorted by maze, task,
/// configuration and seed. `paper_budget_share` is the run's env steps over
/// the paper's 100k iterations × envs × rollout.
pub fn scores_csv(runs: &[RunResult], paper_iterations: u64) -> String {
    let mut rows: Vec<&RunResult> = runs.iter().collect();
    rows.sort_by(|a, b| {
        (&a.maze, &a.task, &a.config, a.seed).cmp(&(&b.maze, &b.task, &b.config, b.seed))
    });
    let mut out = SCORES_COLUMNS.join(",");
    out.push('\n');
    for r in rows {
        let agent = &r.train_config.agent;
        let paper = paper_iterations as f64 * (agent.envs * agent.rollout_len) as f64;
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{:.6},{:.1},{:.0},{},{},{}",
            r.maze,
            r.task,
            r.config,
            r.seed,
            r.test_score,
            r.test_return,
            r.test_success_rate,
            r.best_validation,
            r.best_env_steps,
            r.env_steps,
            r.train_config.eval_every,
            r.env_steps as f64 / paper,
            r.wall_seconds,
            r.train_steps_per_sec,
            r.torch_threads,
            r.jobs,
            r.commit
        );
    }
    out
}
