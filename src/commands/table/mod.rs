//! `worldgraph table results/`: the committed run summaries as the paper's
//! Tables 1 and 2 (section 5), each cell mean ± std over the training seeds
//! with the paper's value beside it, the budget every cell used, the time
//! each configuration took to reach a score, the rows short of their seeds
//! with the command that runs each, and validation curves like the paper's
//! Figure 4 (mean and spread over seeds), into the result set's own
//! `README.md` with its figures in `figures/` beside it (`--out`
//! elsewhere); or one page from several sets (`--with`).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use sim::atomic_file::write_atomic;

use crate::results::{DiscoverResult, RunResult, read_all_discoveries, read_all_runs};

mod budgets;
mod curves;
mod discoveries;
mod missing;
mod paper;
mod sets;
mod tables;
mod time_to_score;

use self::paper::{MAZES, PAPER_ITERATIONS, TABLE1_CONFIGS, TASKS, rank};

/// `table` options.
#[derive(Debug, Clone, Args)]
pub struct TableArgs {
    /// The results directory (`results/<maze>/<task>/<config>/seed-<n>.json`).
    #[arg(default_value = "results")]
    pub results: PathBuf,
    /// The Markdown file written [default: `README.md` in the results
    /// directory, so a result set is one folder: its grid file, its
    /// summaries, its tables and figures].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Directory of the figures (linked from the Markdown file relative to
    /// it) [default: `figures/` beside --out].
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Write the tables only, without figures: a README of a few KB for a
    /// probe set of a few runs (each summary's `validation_curve` holds its
    /// curve; `table` without this flag draws them).
    #[arg(long, conflicts_with = "figures")]
    pub no_figures: bool,
    /// Time to score: the threshold per maze and task, as a share of the
    /// best configuration's score there (its mean over seeds of the runs'
    /// best validation scores, so one lucky seed does not set the bar).
    #[arg(long, default_value_t = 0.9)]
    pub threshold: f64,
    /// A result set of the flat A2C trained longer than this grid (e.g.
    /// `results/a2c-plateau-18m`), used as the time-to-score reference row
    /// where it has runs of a maze and task and the grid's own A2C left a
    /// seed short of the threshold within the grid's budget: the speed-up
    /// over A2C is then defined all the same. Where every seed of the grid's
    /// A2C reached it, the grid's row stays the reference (exact, and timed
    /// beside the grid's runs). Checked to hold only A2C runs on the grid's
    /// validation protocol and agent shape, each at least as long as the
    /// grid's runs. Repeatable (one set per maze, say); where two sets hold
    /// the same maze and task, the one trained longest is the reference.
    #[arg(long, value_name = "DIR")]
    pub reference: Vec<PathBuf>,
    /// The tidy per-run CSV written (one row per run: maze, task, config,
    /// seed, test score, budget, wall time, commit ...) [default:
    /// `scores.csv` in the results directory; with --with, the --out file
    /// with `.csv` for `.md`].
    #[arg(long)]
    pub scores: Option<PathBuf>,
    /// Another result set on the same page, read after RESULTS and the
    /// --with sets before it: each maze and task it holds (a block of
    /// rows) replaces that block of the sets before it whole, so a block's
    /// rows share one grid, budget and version of the code (e.g. the
    /// paper's grid with the Door-Key blocks a later grid re-ran:
    /// `table results/paper-real --with results/doorkey-fixed --out
    /// docs/results.md`). The page lists what each set gives. Refused when
    /// a maze would mix two sets' budgets. Repeatable; needs --out.
    #[arg(long = "with", value_name = "DIR", requires = "out")]
    pub with: Vec<PathBuf>,
}

/// Where the figures are saved (`dir`) and how the README links them
/// (`link`, relative to the README).
pub(super) struct Figures {
    dir: PathBuf,
    link: String,
}

/// The runs of one cell (maze, task, configuration), one per seed.
type Cells<'a> = BTreeMap<(String, String, String), Vec<&'a RunResult>>;

fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = if xs.len() > 1 {
        xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, v.sqrt())
}

/// Runs `worldgraph table`: reads the result set (and the `--reference`
/// sets), writes the README with its figures, then `scores.csv`.
pub fn run(a: TableArgs) -> anyhow::Result<std::process::ExitCode> {
    let out = a.out.clone().unwrap_or_else(|| a.results.join("README.md"));
    anyhow::ensure!(
        !out.is_dir(),
        "--out {} is a directory; name the Markdown file to write (e.g. {}/results.md)",
        out.display(),
        out.display()
    );
    let (runs, nested, discovered, shares, grids) = read_sets(&a)?;
    if runs.is_empty() {
        return discoveries_only(&a, &out, &discovered);
    }
    anyhow::ensure!(
        a.threshold > 0.0 && a.threshold <= 1.0,
        "--threshold must be in (0, 1]"
    );
    let reference = load_reference(&a.reference, &runs)?;
    let out_dir = out.parent().unwrap_or(Path::new(".")).to_path_buf();
    let figures = if a.no_figures {
        None
    } else {
        let dir = a.figures.clone().unwrap_or_else(|| out_dir.join("figures"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let link = pathdiff(&dir, &out_dir);
        Some(Figures { dir, link })
    };
    let cells = cells_of(&runs);
    let mut md = readme(
        &a,
        &runs,
        &nested,
        &shares,
        &grids,
        &cells,
        reference.as_ref(),
        figures.as_ref(),
    )?;
    md.push_str(&discoveries::section(&discovered));
    write_atomic(&out, md.as_bytes())?;
    let scores = a
        .scores
        .clone()
        .unwrap_or_else(|| sets::default_scores(&a.results, &out, !a.with.is_empty()));
    write_atomic(
        &scores,
        super::aggregate::scores_csv(&runs, PAPER_ITERATIONS).as_bytes(),
    )?;
    eprintln!(
        "table: {} runs in {} cells → {} ({}, one row per run in {})",
        runs.len(),
        cells.len(),
        out.display(),
        figures.map_or_else(
            || "no figures".to_string(),
            |f| format!("figures in {}", f.dir.display())
        ),
        scores.display()
    );
    Ok(std::process::ExitCode::SUCCESS)
}

/// The runs, the result sets below those named (not read), the discoveries,
/// with `--with` what each set gives the page (empty without), and the grid
/// files the sets keep.
type Sets = (
    Vec<RunResult>,
    Vec<PathBuf>,
    Vec<DiscoverResult>,
    Vec<sets::SetShare>,
    Vec<missing::KeptGrid>,
);

/// Reads `a.results` and the `--with` sets, merged block by block.
fn read_sets(a: &TableArgs) -> anyhow::Result<Sets> {
    let mut all = Vec::new();
    let mut nested = Vec::new();
    let mut discovered = Vec::new();
    let mut grids = Vec::new();
    for dir in std::iter::once(&a.results).chain(&a.with) {
        let d = read_all_discoveries(dir)?;
        let (runs, n) = read_result_set(dir, !d.is_empty())?;
        grids.extend(missing::kept_grids(dir, &runs));
        discovered.push(d);
        nested.extend(n);
        all.push((dir.clone(), runs));
    }
    if a.with.is_empty() {
        let (_, runs) = all.pop().expect("one set");
        let d = discovered.pop().expect("one set");
        return Ok((runs, nested, d, Vec::new(), grids));
    }
    let (runs, shares) = sets::merge(all)?;
    for s in shares.iter().filter(|s| s.runs == 0) {
        eprintln!(
            "table: every block of {} is replaced by a later --with set; none of its runs is on the page",
            s.dir.display()
        );
    }
    Ok((
        runs,
        nested,
        sets::merge_discoveries(discovered),
        shares,
        grids,
    ))
}

/// The run summaries of the result set `results` and the result sets below
/// it, which are not read (each is named on stderr); an error when there
/// is no summary to read, of a run or (`has_discoveries`) of a discovery.
fn read_result_set(
    results: &Path,
    has_discoveries: bool,
) -> anyhow::Result<(Vec<RunResult>, Vec<PathBuf>)> {
    let (runs, nested) = read_all_runs(results)?;
    for n in &nested {
        eprintln!(
            "table: {} is a result set of its own (another grid or budget), not read: `worldgraph table {}`",
            n.display(),
            n.display()
        );
    }
    anyhow::ensure!(
        !runs.is_empty() || has_discoveries,
        "no run summaries under {} (`worldgraph experiment GRID.toml` writes them){}",
        results.display(),
        if nested.is_empty() {
            String::new()
        } else {
            format!(
                "; result sets below it: {}",
                nested
                    .iter()
                    .map(|n| n.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
    );
    Ok((runs, nested))
}

/// A result set of discoveries alone (`experiment --discoveries-only`, or a
/// grid whose training runs have not finished): its README is the world
/// graph section.
fn discoveries_only(
    a: &TableArgs,
    out: &Path,
    discovered: &[DiscoverResult],
) -> anyhow::Result<std::process::ExitCode> {
    let md = format!(
        "# Results: discoveries only\n\n\
         Generated by `worldgraph table {}` from the {} discovery summaries under `{}/` \
         (written by `worldgraph experiment`, grids in `experiments/`); no training run of \
         this set has finished. Do not edit by hand.\n\n{}",
        a.results.display(),
        discovered.len(),
        a.results.display().to_string().trim_end_matches('/'),
        discoveries::section(discovered)
    );
    write_atomic(out, md.as_bytes())?;
    eprintln!(
        "table: {} discoveries, no training run → {}",
        discovered.len(),
        out.display()
    );
    Ok(std::process::ExitCode::SUCCESS)
}

/// The longer flat A2C of `--reference` (`None` without one), checked
/// against the grid's `runs`; what it leaves out is named on stderr.
fn load_reference(
    dirs: &[PathBuf],
    runs: &[RunResult],
) -> anyhow::Result<Option<time_to_score::Reference>> {
    if dirs.is_empty() {
        return Ok(None);
    }
    let (r, left_out) = time_to_score::Reference::load(dirs, runs)?;
    for note in left_out {
        eprintln!("table: {note}; left out");
    }
    Ok(Some(r))
}

/// The runs grouped by cell (maze, task, configuration).
fn cells_of(runs: &[RunResult]) -> Cells<'_> {
    let mut cells: Cells = BTreeMap::new();
    for r in runs {
        cells
            .entry((r.maze.clone(), r.task.clone(), r.config.clone()))
            .or_default()
            .push(r);
    }
    cells
}

/// The README, section by section: the preamble, the budgets, the time to
/// score (the headline, put right after the budgets), the paper's Tables 1
/// and 2 (section 5) with the rows not yet run and their commands, the
/// rliable aggregates, the budget per cell, and the validation curves (the
/// paper's Figure 4, then every configuration's), whose figures are saved
/// into `figures` (none without it).
#[allow(clippy::too_many_arguments)]
fn readme(
    a: &TableArgs,
    runs: &[RunResult],
    nested: &[PathBuf],
    shares: &[sets::SetShare],
    grids: &[missing::KeptGrid],
    cells: &Cells,
    reference: Option<&time_to_score::Reference>,
    figures: Option<&Figures>,
) -> anyhow::Result<String> {
    let mazes: Vec<&str> = MAZES
        .iter()
        .copied()
        .filter(|m| runs.iter().any(|r| r.maze == *m))
        .collect();
    let mut pairs: Vec<(String, String)> = cells
        .keys()
        .map(|(m, t, _)| (m.clone(), t.clone()))
        .collect();
    pairs.dedup();
    let mut md = preamble(a, runs, nested);
    if !shares.is_empty() {
        md.push_str(&sets::section(shares));
    }
    md.push_str(&budgets::section(runs, &mazes));
    md.push_str(&time_to_score::section(
        cells,
        &pairs,
        a.threshold,
        reference,
        figures,
    )?);
    md.push_str(&tables::table1(runs, cells, &mazes));
    md.push_str(&tables::table2(runs, cells, &mazes));
    let tasks: Vec<&str> = TASKS
        .iter()
        .copied()
        .filter(|t| runs.iter().any(|r| r.task == *t))
        .collect();
    let giver = |m: &str, t: &str| -> Option<PathBuf> {
        let block = (m.to_string(), t.to_string());
        if shares.is_empty() {
            pairs.contains(&block).then(|| a.results.clone())
        } else {
            shares
                .iter()
                .find(|s| s.blocks.contains(&block))
                .map(|s| s.dir.clone())
        }
    };
    md.push_str(&missing::section(cells, &mazes, &tasks, grids, &giver));
    md.push_str(&super::aggregate::section(
        runs,
        &super::aggregate::Layout {
            display: display_config,
            config_rank: |c: &str| rank(&TABLE1_CONFIGS, c),
            cell_rank: |m: &str, t: &str| (rank(&MAZES, m), rank(&TASKS, t)),
        },
    ));
    md.push_str(&budgets::per_cell(runs, cells, &mazes));
    match figures {
        Some(f) => {
            md.push_str(&curves::figure4(cells, &pairs, &f.dir, &f.link)?);
            md.push_str(&curves::every_configuration(
                cells, &pairs, &f.dir, &f.link,
            )?);
        }
        None => md.push_str(
            "## Validation curves\n\nNot drawn (`table --no-figures`): each run summary's \
             `validation_curve` holds its curve.\n",
        ),
    }
    Ok(md)
}

/// The README's opening: its title, the command that generated it, the
/// result sets below `a.results` that were not read, the protocol (section
/// 5) and the commits the runs were made on.
fn preamble(a: &TableArgs, runs: &[RunResult], nested: &[PathBuf]) -> String {
    let mut md = String::new();
    let commits: BTreeSet<&str> = runs.iter().map(|r| r.commit.as_str()).collect();
    let _ = writeln!(
        md,
        "# Results: the paper's Tables 1 and 2 on this machine\n\n\
         Generated by `worldgraph table {}{}{}` from the {} run summaries {} \
         (written by `worldgraph experiment`, grids in `experiments/`); do not edit by hand.\n",
        a.results.display(),
        a.with
            .iter()
            .map(|r| format!(" --with {}", r.display()))
            .chain(
                a.out
                    .iter()
                    .filter(|_| !a.with.is_empty())
                    .map(|o| format!(" --out {}", o.display()))
            )
            .collect::<String>(),
        a.reference
            .iter()
            .map(|r| format!(" --reference {}", r.display()))
            .collect::<String>(),
        runs.len(),
        if a.with.is_empty() {
            format!(
                "under `{}/`",
                a.results.display().to_string().trim_end_matches('/')
            )
        } else {
            "of the result sets below".to_string()
        }
    );
    if !nested.is_empty() {
        let _ = writeln!(
            md,
            "Result sets of other grids or budgets below it, not read here (a table never mixes \
             budgets): {}.\n",
            nested
                .iter()
                .map(|n| format!("`{}`", n.display()))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = writeln!(
        md,
        "**Protocol** (section 5): every run trains on its own seed; validation on {} seeds \
         (environments of stream {}) every `eval_every` env steps keeps the best checkpoint, \
         which is scored on {} held-out test seeds (stream {}). A cell is the mean ± std \
         (sample std) of the test score over the training seeds (3 unless `n=` says otherwise). \
         **Fail** is the paper's rule: the validation score never rose above 0, in every seed \
         of the cell; `(k fail)` counts the seeds that failed in a cell that did not. \
         MultiGoal tasks report the mean test reward, Door-Key the success rate in %. \
         `—`: not run yet. The paper's values are its Tables 1 and 2 (mean reward, or \
         success rate ± std, after 100k training iterations).\n",
        runs[0].validation_seeds,
        runs[0].validation_stream,
        runs[0].test_seeds,
        runs[0].test_stream
    );
    let _ = writeln!(
        md,
        "Runs were made on the commit(s) {}.\n",
        commits
            .iter()
            .map(|c| format!("`{}`", &c[..c.len().min(12)]))
            .collect::<Vec<_>>()
            .join(", ")
    );
    md
}

/// The paper's name of configuration `c` (`WN V_p + traversal + π_g
/// init`); a name no agent has is shown as it is.
fn display_config(c: &str) -> String {
    learner::hrl::AgentConfig::from_name(c, &learner::hrl::AgentConfig::default())
        .map_or_else(|_| c.to_string(), |cfg| cfg.label())
}

/// `to` relative to `from` when it lies below it, else `to` as given.
fn pathdiff(to: &Path, from: &Path) -> String {
    to.strip_prefix(from)
        .map(|p| p.display().to_string())
        .unwrap_or_else(|_| to.display().to_string())
}
