//! `table A --with B --with C`: one page from several result sets, as
//! `docs/results.md` shows the paper's grid with the blocks that later
//! grids re-ran on fixed code. A block is one maze and task (a column of
//! Table 1 or 2); each comes whole from the last set named that holds it,
//! so the rows of a block share one grid, budget and version of the code,
//! and its time to score compares runs of one grid.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::results::{DiscoverResult, RunResult};

/// One result set of the page and what it gives it.
pub(super) struct SetShare {
    /// The set's directory, as named on the command line.
    pub dir: PathBuf,
    /// Its (maze, task) blocks on the page.
    pub blocks: BTreeSet<(String, String)>,
    /// Its runs on the page.
    pub runs: usize,
    /// The grid files of those runs.
    pub grids: BTreeSet<String>,
    /// The commits of those runs.
    pub commits: BTreeSet<String>,
}

/// The runs of `sets` (each a directory and its runs, in the order named)
/// merged block by block, later sets replacing earlier ones; with what
/// each set gives. Refused when a maze would mix budgets from two sets (a
/// table never mixes budgets).
pub(super) fn merge(
    sets: Vec<(PathBuf, Vec<RunResult>)>,
) -> anyhow::Result<(Vec<RunResult>, Vec<SetShare>)> {
    let mut merged: Vec<(usize, RunResult)> = Vec::new();
    let dirs: Vec<PathBuf> = sets.iter().map(|(d, _)| d.clone()).collect();
    for (i, (_, runs)) in sets.into_iter().enumerate() {
        let blocks: BTreeSet<(String, String)> = runs
            .iter()
            .map(|r| (r.maze.clone(), r.task.clone()))
            .collect();
        merged.retain(|(_, r)| !blocks.contains(&(r.maze.clone(), r.task.clone())));
        merged.extend(runs.into_iter().map(|r| (i, r)));
    }
    check_budgets(&merged, &dirs)?;
    let shares = dirs
        .iter()
        .enumerate()
        .map(|(i, dir)| {
            let mine: Vec<&RunResult> = merged
                .iter()
                .filter(|(j, _)| *j == i)
                .map(|(_, r)| r)
                .collect();
            SetShare {
                dir: dir.clone(),
                blocks: mine
                    .iter()
                    .map(|r| (r.maze.clone(), r.task.clone()))
                    .collect(),
                runs: mine.len(),
                grids: mine.iter().map(|r| r.grid.clone()).collect(),
                commits: mine.iter().map(|r| short(&r.commit)).collect(),
            }
        })
        .collect();
    Ok((merged.into_iter().map(|(_, r)| r).collect(), shares))
}

/// Refuses a maze whose runs on the page come from two sets with different
/// budgets (env steps trained).
fn check_budgets(merged: &[(usize, RunResult)], dirs: &[PathBuf]) -> anyhow::Result<()> {
    let mut by_maze: BTreeMap<&str, BTreeMap<u64, BTreeSet<usize>>> = BTreeMap::new();
    for (i, r) in merged {
        by_maze
            .entry(r.maze.as_str())
            .or_default()
            .entry(r.env_steps)
            .or_default()
            .insert(*i);
    }
    for (maze, budgets) in by_maze {
        let sets: BTreeSet<usize> = budgets.values().flatten().copied().collect();
        anyhow::ensure!(
            budgets.len() == 1 || sets.len() == 1,
            "the {maze} maze would mix budgets from two result sets ({}); a table never mixes \
             budgets: name one set per budget, or put the one with the other budget on a page \
             of its own",
            budgets
                .iter()
                .map(|(steps, s)| format!(
                    "{steps} env steps from {}",
                    s.iter()
                        .map(|i| dirs[*i].display().to_string())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(())
}

/// The discoveries of every set, each once (the same discovery is often
/// copied into several sets that reuse it).
pub(super) fn merge_discoveries(sets: Vec<Vec<DiscoverResult>>) -> Vec<DiscoverResult> {
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for d in sets.into_iter().flatten() {
        let key = (
            d.spec.maze.clone(),
            d.spec.seed,
            d.commit.clone(),
            d.summary.to_string(),
        );
        if seen.insert(key) {
            out.push(d);
        }
    }
    out
}

/// The "Result sets" section of a page read from several sets: per set,
/// the blocks (maze: tasks) it gives, its runs, grid files and commits.
pub(super) fn section(shares: &[SetShare]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## Result sets\n\n\
         Each maze and task (a block of rows) comes whole from the last set below that holds \
         it, so the rows of a block share one grid, budget and version of the code; a set's \
         grid file in its folder names its settings.\n\n\
         | result set | maze: tasks | runs | grid | commits |\n|---|---|---:|---|---|"
    );
    for s in shares {
        let mut by_maze: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for (m, t) in &s.blocks {
            by_maze.entry(m).or_default().push(t);
        }
        let blocks = if by_maze.is_empty() {
            "none (replaced by later sets)".to_string()
        } else {
            by_maze
                .iter()
                .map(|(m, ts)| format!("{m}: {}", ts.join(", ")))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let _ = writeln!(
            md,
            "| `{}` | {blocks} | {} | {} | {} |",
            s.dir.display(),
            s.runs,
            join_ticked(&s.grids),
            join_ticked(&s.commits)
        );
    }
    let _ = writeln!(md);
    md
}

/// The Markdown file's scores CSV when `--scores` is not given: with
/// several sets, beside the page (`docs/results.md` → `docs/results.csv`),
/// so that no set's own `scores.csv` is overwritten by the merged rows;
/// else the set's `scores.csv`.
pub(super) fn default_scores(results: &Path, out: &Path, combined: bool) -> PathBuf {
    if combined {
        out.with_extension("csv")
    } else {
        results.join("scores.csv")
    }
}

fn short(commit: &str) -> String {
    commit[..commit.len().min(12)].to_string()
}

fn join_ticked(xs: &BTreeSet<String>) -> String {
    xs.iter()
        .map(|x| format!("`{x}`"))
        .collect::<Vec<_>>()
        .join(", ")
}
