//! `table`'s "Not run yet" section: every row of Tables 1 and 2 on the page
//! with fewer seeds than its grid asks, with the `experiment` command that
//! runs it (a run stopped part-way resumes from its checkpoint, and the
//! runs done are skipped), so an unfinished table says how to finish it.
//!
//! A row's grid is one a result set keeps beside its summaries
//! (`<set>/<grid name>.toml`, written by `experiment`). A block (maze,
//! task) with runs on the page takes its missing rows from the grids of
//! the set that gave it, since a run added to another set would not show
//! in the block; a block with none from the last set whose grid declares
//! the row.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use sim::{Maze, Task};

use crate::commands::experiment::Grid;
use crate::results::RunResult;

use super::paper::{TABLE1_CONFIGS, TABLE1_TASKS, TABLE2_CONFIGS};
use super::{Cells, display_config};

/// A grid file a result set keeps beside its summaries.
pub(super) struct KeptGrid {
    /// The result set (the command's `--results`).
    pub set: PathBuf,
    /// The grid as the command names it: the path the set's runs recorded
    /// (`experiments/<name>.toml`) when one of them names this grid, else
    /// the kept copy.
    pub file: String,
    /// Its content.
    pub grid: Grid,
}

/// The grid files kept in result set `set`, whose runs are `runs`: every
/// `*.toml` directly in it that reads as a grid (one that does not is
/// named on stderr and left out).
pub(super) fn kept_grids(set: &Path, runs: &[RunResult]) -> Vec<KeptGrid> {
    let Ok(entries) = std::fs::read_dir(set) else {
        return Vec::new();
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for path in paths {
        let grid = match std::fs::read_to_string(&path)
            .map_err(anyhow::Error::from)
            .and_then(|t| Ok(toml::from_str::<Grid>(&t)?))
        {
            Ok(g) => g,
            Err(e) => {
                eprintln!(
                    "table: {} is not a grid file ({e}); the rows it would run are not listed",
                    path.display()
                );
                continue;
            }
        };
        let name = path.file_name().expect("a file");
        let file = runs
            .iter()
            .map(|r| r.grid.as_str())
            .find(|g| Path::new(g).file_name() == Some(name))
            .map_or_else(|| path.display().to_string(), str::to_string);
        out.push(KeptGrid {
            set: set.to_path_buf(),
            file,
            grid,
        });
    }
    out
}

/// One row of the page left short of its seeds.
struct Missing {
    maze: String,
    task: String,
    config: String,
    done: usize,
    /// The grid that runs it, or `None` when no grid of the page's sets
    /// declares it.
    by: Option<(usize, Vec<u64>)>,
}

/// The section: the rows of the page's tables (mazes `mazes`, tasks
/// `tasks`) short of their seeds. `grids` are the kept grids of every set
/// in the order named; `giver` names, for a block with runs on the page,
/// the set that gave it.
pub(super) fn section(
    cells: &Cells,
    mazes: &[&str],
    tasks: &[&str],
    grids: &[KeptGrid],
    giver: &dyn Fn(&str, &str) -> Option<PathBuf>,
) -> String {
    let mut rows = Vec::new();
    for &m in mazes {
        for &t in tasks {
            let (Ok(maze), Ok(task)) = (m.parse::<Maze>(), t.parse::<Task>()) else {
                continue;
            };
            let block_set = giver(m, t);
            let eligible = |g: &KeptGrid| block_set.as_ref().is_none_or(|s| *s == g.set);
            for c in configs_of(t, grids, maze, task) {
                let done: BTreeSet<u64> = cells
                    .get(&(m.to_string(), t.to_string(), c.to_string()))
                    .map(|rs| rs.iter().map(|r| r.seed).collect())
                    .unwrap_or_default();
                let by = grids
                    .iter()
                    .enumerate()
                    .rev()
                    .find(|(_, g)| eligible(g) && g.grid.declares(maze, task, &c))
                    .map(|(i, g)| {
                        let left: Vec<u64> = g
                            .grid
                            .seeds
                            .iter()
                            .copied()
                            .filter(|s| !done.contains(s))
                            .collect();
                        (i, left)
                    });
                let short = match &by {
                    Some((_, left)) => !left.is_empty(),
                    None => done.len() < 3,
                };
                if short {
                    rows.push(Missing {
                        maze: m.to_string(),
                        task: t.to_string(),
                        config: c,
                        done: done.len(),
                        by,
                    });
                }
            }
        }
    }
    render(&rows, grids)
}

/// The rows of task `t`'s table: Table 1's configurations, or Table 2's
/// with the flat A2C first when a grid declares it there.
fn configs_of(t: &str, grids: &[KeptGrid], maze: Maze, task: Task) -> Vec<String> {
    if TABLE1_TASKS.contains(&t) {
        return TABLE1_CONFIGS.iter().map(|c| c.to_string()).collect();
    }
    let a2c = grids.iter().any(|g| g.grid.declares(maze, task, "a2c"));
    a2c.then_some("a2c")
        .into_iter()
        .chain(TABLE2_CONFIGS)
        .map(str::to_string)
        .collect()
}

fn render(rows: &[Missing], grids: &[KeptGrid]) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "## Not run yet\n");
    if rows.is_empty() {
        let _ = writeln!(
            md,
            "Every row of the tables above has the seeds its grid asks for.\n"
        );
        return md;
    }
    let _ = writeln!(
        md,
        "Each row of the tables above with fewer seeds than its grid asks, and the command \
         that runs it: the runs done are skipped, and one stopped part-way resumes from its \
         last checkpoint (`experiment --slurm` with the same filters submits it to a \
         cluster). A block with runs on the page takes the grid of the set that gave it. A \
         row no grid of these sets declares has no command: add its configuration to a \
         grid's group first.\n\n\
         | maze | task | configuration | seeds done | seeds left | command |\n\
         |---|---|---|---:|---|---|"
    );
    for r in rows {
        let (left, command) = match &r.by {
            Some((i, left)) => {
                let g = &grids[*i];
                (
                    left.iter()
                        .map(u64::to_string)
                        .collect::<Vec<_>>()
                        .join(", "),
                    format!(
                        "`worldgraph experiment {} --maze {} --task {} --config {} --results {}`",
                        g.file,
                        r.maze,
                        r.task,
                        r.config,
                        g.set.display()
                    ),
                )
            }
            None => ("—".to_string(), "in no grid of these sets".to_string()),
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {left} | {command} |",
            r.maze,
            r.task,
            display_config(&r.config),
            r.done
        );
    }
    let _ = writeln!(md);
    md
}
