//! `table`'s aggregate section and `scores.csv`: the run summaries reported
//! the way deep RL reports results today (the `rliable` protocol, Agarwal
//! et al. 2021; the statistics are in [`crate::rliable`]).
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
use crate::rliable::{
    BOOTSTRAP_REPS, BOOTSTRAP_SEED, Estimate, improvement_interval, iqm_interval,
};

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

/// How the section names and sorts things: `display` names a configuration
/// as the paper does, `config_rank` sorts configurations (Table 1's order)
/// and `cell_rank` sorts (maze, task) cells (small to large, the paper's
/// task order).
pub struct Layout<D, C, K>
where
    D: Fn(&str) -> String,
    C: Fn(&str) -> usize,
    K: Fn(&str, &str) -> (usize, usize),
{
    /// A configuration's name in the paper.
    pub display: D,
    /// A configuration's sort key.
    pub config_rank: C,
    /// A (maze, task) cell's sort key.
    pub cell_rank: K,
}

/// The strata where both `x` and `y` ran, sorted by `cell_rank`.
fn paired_strata<'a>(
    s: &'a Scores,
    x: &str,
    y: &str,
    cell_rank: &impl Fn(&str, &str) -> (usize, usize),
) -> Vec<Stratum<'a>> {
    let mut strata: Vec<Stratum<'a>> = s
        .iter()
        .filter(|((_, _, c), _)| c == x)
        .filter_map(|((m, t, _), v)| {
            let w = s.get(&(m.clone(), t.clone(), y.to_string()))?;
            Some((m.as_str(), t.as_str(), v.as_slice(), w.as_slice()))
        })
        .collect();
    strata.sort_by_key(|(m, t, _, _)| cell_rank(m, t));
    strata
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

/// The Markdown section over the runs' test scores.
pub fn section<D, C, K>(runs: &[RunResult], layout: &Layout<D, C, K>) -> String
where
    D: Fn(&str) -> String,
    C: Fn(&str) -> usize,
    K: Fn(&str, &str) -> (usize, usize),
{
    section_of(&scores_of(runs), layout)
}

/// The section of [`section`] over the test scores `s`: its introduction,
/// the IQM table, then the probability of improvement.
fn section_of<D, C, K>(s: &Scores, layout: &Layout<D, C, K>) -> String
where
    D: Fn(&str) -> String,
    C: Fn(&str) -> usize,
    K: Fn(&str, &str) -> (usize, usize),
{
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
    md.push_str(&iqm_table(s, layout));
    md.push_str(&improvement(s, layout));
    md
}

/// The IQM table: every configuration's interquartile mean over its seeds
/// with its stratified bootstrap interval, per maze and task in
/// `cell_rank`'s order, configurations in `config_rank`'s.
fn iqm_table<D, C, K>(s: &Scores, layout: &Layout<D, C, K>) -> String
where
    D: Fn(&str) -> String,
    C: Fn(&str) -> usize,
    K: Fn(&str, &str) -> (usize, usize),
{
    let Layout {
        display,
        config_rank: order,
        cell_rank,
    } = layout;
    let mut md = String::new();
    let mut cells: Vec<(String, String)> =
        s.keys().map(|(m, t, _)| (m.clone(), t.clone())).collect();
    cells.dedup();
    cells.sort_by_key(|(m, t)| cell_rank(m, t));
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
    md
}

/// The probability of improvement: every comparison of [`comparisons`]
/// pooled over the mazes and tasks where both configurations ran, then the
/// same per maze and task; a single line saying so when no comparison had
/// both configurations on one maze and task.
fn improvement<D, C, K>(s: &Scores, layout: &Layout<D, C, K>) -> String
where
    D: Fn(&str) -> String,
    C: Fn(&str) -> usize,
    K: Fn(&str, &str) -> (usize, usize),
{
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n### Probability of improvement\n\n\
         | X over Y | mazes × tasks | runs of X / of Y | P(X > Y) [95 % CI] |\n|---|---:|---:|---|"
    );
    let rows = comparisons(s, &layout.display, &layout.config_rank);
    let strata: Vec<Vec<Stratum>> = rows
        .iter()
        .map(|(x, y, _)| paired_strata(s, x, y, &layout.cell_rank))
        .collect();
    let pooled = pooled_rows(&rows, &strata);
    if pooled.is_empty() {
        let _ = writeln!(
            md,
            "| (no pair of configurations ran on the same maze and task) | | | |\n"
        );
        return md;
    }
    md.push_str(&pooled);
    md.push_str(&per_cell_rows(&rows, &strata));
    md
}

/// The pooled rows of the probability of improvement, one per comparison
/// with at least one maze and task where both ran (`strata[i]` those of
/// `rows[i]`); empty when there is none.
fn pooled_rows(rows: &[(String, String, String)], strata: &[Vec<Stratum>]) -> String {
    let mut md = String::new();
    for ((_, _, what), here) in rows.iter().zip(strata) {
        let xs: Vec<Vec<f64>> = here.iter().map(|(_, _, x, _)| x.to_vec()).collect();
        let ys: Vec<Vec<f64>> = here.iter().map(|(_, _, _, y)| y.to_vec()).collect();
        let Some(e) = improvement_interval(&xs, &ys, LEVEL, BOOTSTRAP_REPS, BOOTSTRAP_SEED) else {
            continue;
        };
        let nx: usize = xs.iter().map(Vec::len).sum();
        let ny: usize = ys.iter().map(Vec::len).sum();
        let _ = writeln!(
            md,
            "| {what} | {} | {nx} / {ny} | {} |",
            xs.len(),
            interval_text(&e, 2)
        );
    }
    md
}

/// The per maze and task table of the probability of improvement: each
/// comparison of `rows` on each of its strata alone, the bootstrap
/// resampling that cell's runs.
fn per_cell_rows(rows: &[(String, String, String)], strata: &[Vec<Stratum>]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n#### Per maze and task\n\n\
         The same comparisons on each maze and task alone (the bootstrap resamples that cell's \
         runs).\n\n\
         | X over Y | maze | task | runs of X / of Y | P(X > Y) [95 % CI] |\n|---|---|---|---:|---|"
    );
    for ((_, _, what), here) in rows.iter().zip(strata) {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn scores(cells: &[(&str, &str, &str, &[f64])]) -> Scores {
        cells
            .iter()
            .map(|(m, t, c, v)| ((m.to_string(), t.to_string(), c.to_string()), v.to_vec()))
            .collect()
    }

    /// An ordering that holds on one task, fails on another and ties on a
    /// third pools to a coin flip; the per-task table must show each cell's
    /// own value, in the paper's maze and task order (small before medium,
    /// MultiGoal before Door-Key), not the names' alphabetical one.
    #[test]
    fn per_task_rows_show_each_cells_own_improvement_in_the_papers_order() {
        let s = scores(&[
            ("medium", "multigoal", "wn-pivotal-init", &[2.0]),
            ("medium", "multigoal", "wn-random-init", &[2.0]),
            ("small", "doorkey", "wn-pivotal-init", &[0.1, 0.2]),
            ("small", "doorkey", "wn-random-init", &[0.5, 0.6]),
            ("small", "multigoal", "wn-pivotal-init", &[3.0, 4.0]),
            ("small", "multigoal", "wn-random-init", &[1.0, 2.0]),
        ]);
        let rank = |names: &[&str], x: &str| names.iter().position(|n| *n == x).unwrap();
        let md = section_of(
            &s,
            &Layout {
                display: |c: &str| c.to_string(),
                config_rank: |_: &str| 0,
                cell_rank: |m: &str, t: &str| {
                    (
                        rank(&["small", "medium"], m),
                        rank(&["multigoal", "doorkey"], t),
                    )
                },
            },
        );
        let what = "V_p over V_rand (π_g init)";
        // Pooled: the mean of 1, 0 and ½ over the three cells.
        let pooled = md
            .lines()
            .find(|l| l.starts_with(&format!("| {what} | 3 |")))
            .unwrap_or_else(|| panic!("no pooled row in\n{md}"));
        assert!(pooled.contains("| 5 / 5 | 0.50 ["), "{pooled}");
        // Per cell: every resample of a cell keeps X above (or below, or
        // level with) Y, so each interval is its point.
        let per_cell: Vec<&str> = md
            .lines()
            .filter(|l| l.starts_with(&format!("| {what} | ")) && *l != pooled)
            .collect();
        assert_eq!(
            per_cell,
            [
                format!("| {what} | small | multigoal | 2 / 2 | 1.00 [1.00, 1.00] |"),
                format!("| {what} | small | doorkey | 2 / 2 | 0.00 [0.00, 0.00] |"),
                format!("| {what} | medium | multigoal | 1 / 1 | 0.50 [0.50, 0.50] |"),
            ],
            "{md}"
        );
        // The IQM table in the same order.
        let cells: Vec<&str> = md
            .lines()
            .filter(|l| l.contains("| wn-random-init |"))
            .collect();
        assert_eq!(
            cells,
            [
                "| small | multigoal | wn-random-init | 2 | 1.500 [1.000, 2.000] |",
                "| small | doorkey | wn-random-init | 2 | 0.550 [0.500, 0.600] |",
                "| medium | multigoal | wn-random-init | 1 | 2.000 [2.000, 2.000] |",
            ],
            "{md}"
        );
    }
}
