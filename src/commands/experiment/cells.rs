//! The cells of a grid: every run it holds under a fixed index (its
//! discoveries first, then its training runs cell by cell, all seeds of a
//! cell together), the ones the filters select, and which are done. The
//! index depends on the grid file alone, never on the filters: it is what
//! `--cell` takes and what a SLURM array task id is.

use std::collections::HashMap;

use sim::Maze;

use super::grid::{Grid, config_named};
use super::{ExperimentArgs, Job, Plan, discovery_done};
use crate::results::{DiscoverSpec, read_run, run_path};

/// Every run of the grid, by cell index: one discovery per (maze, seed)
/// that a configuration needs, in the order the training runs first need
/// them, then the training runs group by group, task by task, configuration
/// by configuration, seed by seed.
pub(super) fn all_cells(grid: &Grid) -> anyhow::Result<Vec<Job>> {
    let mut discover: HashMap<(Maze, u64), usize> = HashMap::new();
    let mut out = Vec::new();
    let mut train = Vec::new();
    for g in &grid.group {
        for maze in grid.group_mazes(g) {
            for &task in &g.tasks {
                for config in &g.configs {
                    let needs_graph = config_named(config)?.needs_discovery(task);
                    for &seed in &grid.seeds {
                        let needs = needs_graph.then(|| {
                            *discover.entry((maze, seed)).or_insert_with(|| {
                                out.push(Job::Discover {
                                    spec: DiscoverSpec {
                                        maze: maze.name().to_string(),
                                        seed,
                                        rounds: grid.budget(maze).expect("checked").discover_rounds,
                                    },
                                });
                                out.len() - 1
                            })
                        });
                        train.push(Job::Train {
                            maze,
                            task,
                            config: config.clone(),
                            seed,
                            needs,
                        });
                    }
                }
            }
        }
    }
    out.extend(train);
    Ok(out)
}

/// The cells the filters select: the training runs they match and the
/// discoveries those need, discoveries first (with `--discoveries-only`,
/// the discoveries alone).
fn select(all: &[Job], a: &ExperimentArgs) -> anyhow::Result<Vec<usize>> {
    for c in &a.configs {
        config_named(c)?;
    }
    let keep = |j: &Job| match j {
        Job::Train {
            maze,
            task,
            config,
            seed,
            ..
        } => {
            (a.mazes.is_empty() || a.mazes.contains(maze))
                && (a.tasks.is_empty() || a.tasks.contains(task))
                && (a.configs.is_empty() || a.configs.contains(config))
                && (a.seeds.is_empty() || a.seeds.contains(seed))
        }
        Job::Discover { .. } => false,
    };
    let trains: Vec<usize> = (0..all.len()).filter(|&i| keep(&all[i])).collect();
    let mut out: Vec<usize> = trains
        .iter()
        .filter_map(|&i| match &all[i] {
            Job::Train { needs, .. } => *needs,
            Job::Discover { .. } => None,
        })
        .collect();
    out.sort_unstable();
    out.dedup();
    if !a.discoveries_only {
        out.extend(trains);
    }
    Ok(out)
}

/// The filters given, in words: `--maze medium --seed 7`.
fn filters(a: &ExperimentArgs) -> String {
    let mut v: Vec<String> = Vec::new();
    v.extend(a.mazes.iter().map(|m| format!("--maze {}", m.name())));
    v.extend(a.tasks.iter().map(|t| format!("--task {}", t.name())));
    v.extend(a.configs.iter().map(|c| format!("--config {c}")));
    v.extend(a.seeds.iter().map(|s| format!("--seed {s}")));
    if v.is_empty() {
        "none".to_string()
    } else {
        v.join(" ")
    }
}

/// Each filter value the grid has no run of (`--seed 9` in a grid of
/// seeds 0 to 2).
fn unmatched_filters(grid: &Grid, a: &ExperimentArgs) -> Vec<String> {
    let mut out = Vec::new();
    for m in &a.mazes {
        if !grid.group.iter().any(|g| grid.group_mazes(g).contains(m)) {
            out.push(format!("--maze {}", m.name()));
        }
    }
    for t in &a.tasks {
        if !grid.group.iter().any(|g| g.tasks.contains(t)) {
            out.push(format!("--task {}", t.name()));
        }
    }
    for c in &a.configs {
        if !grid.group.iter().any(|g| g.configs.contains(c)) {
            out.push(format!("--config {c}"));
        }
    }
    for s in &a.seeds {
        if !grid.seeds.contains(s) {
            out.push(format!("--seed {s}"));
        }
    }
    out
}

/// Whether a cell is done: a finished discovery in the working directory,
/// or a training run's summary under `results/`. A summary of another
/// budget or protocol is refused, not counted: a cell never mixes budgets.
pub(super) fn is_done(plan: &Plan, job: &Job) -> anyhow::Result<bool> {
    let (maze, task, config, seed) = match job {
        Job::Discover { spec } => {
            return Ok(discovery_done(&plan.discover_dir(spec), spec).is_some());
        }
        Job::Train {
            maze,
            task,
            config,
            seed,
            ..
        } => (maze, task, config, seed),
    };
    let path = run_path(&plan.results, maze.name(), task.name(), config, *seed);
    if !path.exists() {
        return Ok(false);
    }
    let r = read_run(&path)?;
    let want = plan.grid.train_config(*maze);
    let got = &r.train_config;
    anyhow::ensure!(
        (
            got.env_steps,
            got.eval_every,
            got.validation_seeds,
            got.test_seeds
        ) == (
            want.env_steps,
            want.eval_every,
            want.validation_seeds,
            want.test_seeds
        ),
        "{} was run with env_steps {}, eval_every {}, {} validation and {} test seeds; \
         this grid asks for {}, {}, {} and {}: give the grid another --results directory",
        path.display(),
        got.env_steps,
        got.eval_every,
        got.validation_seeds,
        got.test_seeds,
        want.env_steps,
        want.eval_every,
        want.validation_seeds,
        want.test_seeds
    );
    Ok(true)
}

/// The grid's cells for one invocation: all of them, the ones its filters
/// select, and which of those are done.
pub(super) struct Cells {
    /// Every cell of the grid, by index.
    pub all: Vec<Job>,
    /// The indices the filters select, ascending.
    pub selected: Vec<usize>,
    /// Per cell of `all`: done (only the selected ones are looked at).
    pub done: Vec<bool>,
    /// `--discoveries-only`: the selection is discoveries wanted for
    /// themselves.
    pub discoveries_only: bool,
}

impl Cells {
    /// The cells of `plan`'s grid under `a`'s filters; warns of filters
    /// that match nothing.
    pub fn load(plan: &Plan, a: &ExperimentArgs) -> anyhow::Result<Cells> {
        let all = all_cells(&plan.grid)?;
        let selected = select(&all, a)?;
        let grid_path = plan.grid_path.display();
        for f in unmatched_filters(&plan.grid, a) {
            eprintln!("warning: {f} matches no run of {grid_path}");
        }
        if selected.is_empty() {
            eprintln!(
                "warning: the filters ({}) select no run of {grid_path}",
                filters(a)
            );
        }
        let mut done = vec![false; all.len()];
        for &i in &selected {
            done[i] = is_done(plan, &all[i])?;
        }
        Ok(Cells {
            all,
            selected,
            done,
            discoveries_only: a.discoveries_only,
        })
    }

    /// Whether cell `i` must run: a training run without a summary, or a
    /// discovery not finished that such a run needs (with
    /// `--discoveries-only`, any discovery not finished).
    pub fn wanted(&self, i: usize) -> bool {
        if self.done[i] {
            return false;
        }
        match &self.all[i] {
            Job::Train { .. } => true,
            Job::Discover { .. } if self.discoveries_only => true,
            Job::Discover { .. } => self.selected.iter().any(|&k| {
                matches!(self.all[k], Job::Train { needs: Some(n), .. } if n == i) && !self.done[k]
            }),
        }
    }

    /// The selected cells still to run, in index order.
    pub fn todo(&self) -> Vec<usize> {
        self.selected
            .iter()
            .copied()
            .filter(|&i| self.wanted(i))
            .collect()
    }

    /// `(training runs, of them done)` among the selected cells.
    pub fn trains(&self) -> (usize, usize) {
        let trains = || {
            self.selected
                .iter()
                .filter(|&&i| matches!(self.all[i], Job::Train { .. }))
        };
        (
            trains().count(),
            trains().filter(|&&i| self.done[i]).count(),
        )
    }
}
