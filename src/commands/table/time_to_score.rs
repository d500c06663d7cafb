//! Time to score, the headline table of `worldgraph table`: for each maze
//! and task, the env steps and training wall seconds until a
//! configuration's validation score first reaches a threshold, and its
//! speed-up over the flat A2C (the paper's claim is acceleration, section 5).
//!
//! **Censoring.** A seed that never reaches the threshold within its budget
//! has a time to score above that budget, how far above unknown. A mean over
//! a configuration's seeds is therefore exact only when every seed reached
//! the threshold. When some A2C seeds did not, A2C's mean time is at least
//! the mean with each of them counted at its budget, so the speed-up of a
//! configuration whose seeds all reached it is at least that bound over its
//! mean (printed `≥`). A configuration with a seed that did not reach it gets
//! no speed-up: its own mean is unbounded above.
//!
//! **The reference.** A grid's flat A2C may not reach the threshold within
//! the grid's budget at all; `--reference DIR` names a result set of the
//! same A2C trained longer (e.g. `results/a2c-plateau`), checked to share
//! the grid's validation protocol and agent shape, which then serves as the
//! reference row in place of the grid's own A2C where that one left a seed
//! short of the threshold. Where every seed of the grid's A2C reached it,
//! the grid's row stays the reference: it is exact, and its wall seconds
//! were measured beside the grid's own runs.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::chart::{LineChart, Series, XScale};
use crate::results::{RunResult, read_all_runs};

use super::paper::TABLE1_CONFIGS;
use super::{Cells, display_config, mean_std};

/// A seed's time to the threshold, or the budget it ran without reaching
/// it: env steps and training wall seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Time {
    Reached { steps: u64, wall: f64 },
    Censored { steps: u64, wall: f64 },
}

/// The times to score of one cell's seeds.
struct Times(Vec<Time>);

impl Times {
    fn of(rs: &[&RunResult], threshold: f64) -> Times {
        Times(
            rs.iter()
                .map(|r| match first_reach(r, threshold) {
                    Some((steps, wall)) => Time::Reached { steps, wall },
                    // The training wall time at the last validation: at
                    // most the run's, so the bound stays a lower bound.
                    None => Time::Censored {
                        steps: r.env_steps,
                        wall: r.validation_curve.last().map_or(0.0, |p| p.wall_seconds),
                    },
                })
                .collect(),
        )
    }

    fn reached(&self) -> Vec<(u64, f64)> {
        self.0
            .iter()
            .filter_map(|t| match *t {
                Time::Reached { steps, wall } => Some((steps, wall)),
                Time::Censored { .. } => None,
            })
            .collect()
    }

    fn all_reached(&self) -> bool {
        self.0.iter().all(|t| matches!(t, Time::Reached { .. }))
    }

    /// Mean env steps and wall seconds with every censored seed counted at
    /// its budget: the exact mean when every seed reached the threshold,
    /// else a lower bound on it.
    fn mean_at_least(&self) -> (f64, f64) {
        let n = self.0.len() as f64;
        let (s, w) = self.0.iter().fold((0.0, 0.0), |(s, w), t| match *t {
            Time::Reached { steps, wall } | Time::Censored { steps, wall } => {
                (s + steps as f64, w + wall)
            }
        });
        (s / n, w / n)
    }
}

/// The speed-up of `c` over the reference `a2c` (steps / wall), exact or a
/// lower bound; `None` when `c` has a seed that did not reach the threshold.
fn speed_up(a2c: &Times, c: &Times) -> Option<String> {
    if !c.all_reached() || c.0.is_empty() || a2c.0.is_empty() {
        return None;
    }
    let (a_steps, a_wall) = a2c.mean_at_least();
    let (steps, wall) = c.mean_at_least();
    let ge = if a2c.all_reached() { "" } else { "≥ " };
    Some(format!(
        "{ge}{:.2}× / {ge}{:.2}×",
        a_steps / steps,
        a_wall / wall
    ))
}

/// Time to score of one run: the first validation point at or above
/// `threshold` (env steps, wall seconds).
fn first_reach(r: &RunResult, threshold: f64) -> Option<(u64, f64)> {
    r.validation_curve
        .iter()
        .find(|p| p.score >= threshold)
        .map(|p| (p.env_steps, p.wall_seconds))
}

/// The flat A2C trained longer than the grid (`--reference`), per maze and
/// task: the result set it came from and its runs.
pub(super) struct Reference {
    runs: BTreeMap<(String, String), (String, Vec<RunResult>)>,
}

impl Reference {
    /// Reads `dirs` and checks each against the grid's `runs`: only flat A2C
    /// runs, on the grid's validation protocol and agent shape, at least as
    /// long as the grid's budget. Where two sets hold the same maze and task
    /// the longer one is kept. Returns, for a note, what was left out: the
    /// mazes and tasks the grid has not run, and the shorter of two sets.
    pub(super) fn load(
        dirs: &[PathBuf],
        grid: &[RunResult],
    ) -> anyhow::Result<(Reference, Vec<String>)> {
        let mut kept: BTreeMap<(String, String), (String, Vec<RunResult>)> = BTreeMap::new();
        let mut left_out = Vec::new();
        for dir in dirs {
            let (runs, _) = read_all_runs(dir)?;
            anyhow::ensure!(
                !runs.is_empty(),
                "--reference {}: no run summaries there",
                dir.display()
            );
            let mut by_cell: BTreeMap<(String, String), Vec<RunResult>> = BTreeMap::new();
            for r in runs {
                check(dir, &r, grid)?;
                by_cell
                    .entry((r.maze.clone(), r.task.clone()))
                    .or_default()
                    .push(r);
            }
            for ((m, t), rs) in by_cell {
                if !grid.iter().any(|g| g.maze == m && g.task == t) {
                    left_out.push(format!(
                        "--reference {} has {m}/{t}, which this grid has not run",
                        dir.display()
                    ));
                    continue;
                }
                let name = dir.display().to_string();
                let longest = |rs: &[RunResult]| rs.iter().map(|r| r.env_steps).max();
                match kept.get(&(m.clone(), t.clone())) {
                    Some((other, old)) if longest(old) >= longest(&rs) => {
                        left_out.push(format!(
                            "--reference {name}: {m}/{t} is shorter than {other}'s"
                        ));
                    }
                    Some((other, _)) => {
                        left_out.push(format!(
                            "--reference {other}: {m}/{t} is shorter than {name}'s"
                        ));
                        kept.insert((m, t), (name, rs));
                    }
                    None => {
                        kept.insert((m, t), (name, rs));
                    }
                }
            }
        }
        Ok((Reference { runs: kept }, left_out))
    }
}

/// Checks one run of the reference set `dir` against the grid: a flat A2C
/// run, validated and shaped as the grid's runs of its maze and task, at
/// least as long as they are.
fn check(dir: &Path, r: &RunResult, grid: &[RunResult]) -> anyhow::Result<()> {
    let what = format!(
        "--reference {}: {}/{}/{} seed {}",
        dir.display(),
        r.maze,
        r.task,
        r.config,
        r.seed
    );
    anyhow::ensure!(
        r.config == "a2c",
        "{what} is not a flat A2C run; the reference holds the flat A2C trained longer"
    );
    let Some(g) = grid.iter().find(|g| g.maze == r.maze && g.task == r.task) else {
        return Ok(());
    };
    anyhow::ensure!(
        (
            r.validation_stream,
            r.validation_seeds,
            r.train_config.eval_every
        ) == (
            g.validation_stream,
            g.validation_seeds,
            g.train_config.eval_every
        ),
        "{what} is validated on {} seeds of stream {} every {} env steps, the grid on {} \
         of stream {} every {}: its times to score are not comparable",
        r.validation_seeds,
        r.validation_stream,
        r.train_config.eval_every,
        g.validation_seeds,
        g.validation_stream,
        g.train_config.eval_every
    );
    let (ra, ga) = (&r.train_config.agent, &g.train_config.agent);
    anyhow::ensure!(
        (ra.envs, ra.rollout_len) == (ga.envs, ga.rollout_len),
        "{what} ran {} envs × rollout {}, the grid {} × {}",
        ra.envs,
        ra.rollout_len,
        ga.envs,
        ga.rollout_len
    );
    let budget = grid
        .iter()
        .filter(|g| g.maze == r.maze && g.task == r.task)
        .map(|g| g.env_steps)
        .max()
        .unwrap_or(0);
    anyhow::ensure!(
        r.env_steps >= budget,
        "{what} trained {} env steps, fewer than the grid's {budget}: a reference is the \
         flat A2C trained longer",
        r.env_steps
    );
    Ok(())
}

/// How many of the reference's seeds repeat the grid's A2C run of the same
/// seed over the grid's budget (every validation point equal to the last
/// digit), of those both ran.
fn repeats(reference: &[RunResult], grid_a2c: &[&RunResult]) -> (usize, usize) {
    let mut same = 0;
    let mut both = 0;
    for g in grid_a2c {
        let Some(r) = reference.iter().find(|r| r.seed == g.seed) else {
            continue;
        };
        both += 1;
        let prefix: Vec<(u64, f64)> = r
            .validation_curve
            .iter()
            .filter(|p| p.env_steps <= g.env_steps)
            .map(|p| (p.env_steps, p.score))
            .collect();
        let own: Vec<(u64, f64)> = g
            .validation_curve
            .iter()
            .map(|p| (p.env_steps, p.score))
            .collect();
        same += usize::from(prefix == own);
    }
    (same, both)
}

/// The time-to-score section: its table, a row per configuration of each
/// maze and task of `pairs` (the threshold `share` of the best cell's
/// score there), the notes on where each reference row came from, and one
/// reach-share figure per maze and task (written into `figures`, none
/// without it).
pub(super) fn section(
    cells: &Cells,
    pairs: &[(String, String)],
    share: f64,
    reference: Option<&Reference>,
    figures: Option<&super::Figures>,
) -> anyhow::Result<String> {
    let mut tts = intro(share, reference.is_some());
    let mut notes = Vec::new();
    for (m, t) in pairs {
        let Some(threshold) = threshold(cells, m, t, share) else {
            let _ = writeln!(
                tts,
                "| {m} | {t} | — | every configuration | 0 | — | — | — |"
            );
            continue;
        };
        let longer = reference.and_then(|r| r.runs.get(&(m.clone(), t.clone())));
        let mut here = configurations(cells, m, t);
        let chosen = reference_row(cells, m, t, threshold, longer, &mut here, &mut notes);
        let reach_series = rows(&mut tts, m, t, threshold, &here, chosen.name.as_ref());
        if let Some(f) = figures {
            reach_chart(&f.dir, m, t, threshold, reach_series, chosen.longer_used)?;
        }
    }
    let _ = writeln!(tts);
    for n in &notes {
        let _ = writeln!(tts, "{n}\n");
    }
    if let Some(f) = figures {
        for (m, t) in pairs {
            let file = format!("time-to-score-{m}-{t}.png");
            if f.dir.join(&file).exists() {
                let _ = writeln!(tts, "![time to score, {m} {t}]({}/{file})", f.link);
            }
        }
    }
    let _ = writeln!(tts);
    Ok(tts)
}

/// The section's heading and what it measures (the threshold at `share` of
/// the best cell, censoring, the speed-up), the reference row explained
/// when `--reference` named one, and the table's head.
fn intro(share: f64, has_reference: bool) -> String {
    let mut tts = String::new();
    let _ = writeln!(
        tts,
        "## Time to score\n\n\
         For each maze and task the threshold is {:.0} % of the best cell's mean (over its \
         seeds) of the runs' best validation scores; a seed's time to score is the env steps \
         (and training wall seconds) at its first validation at or above it. `k/n` seeds \
         reached it; mean ± std are over those k. The speed-up is the flat A2C's mean time \
         over the configuration's, in env steps and in wall seconds (above 1: faster than \
         A2C). A seed that did not reach the threshold within its budget is censored: its \
         time is above the budget, by an unknown amount. So the speed-up is given only for \
         a configuration every seed of which reached the threshold, and when some A2C seeds \
         did not, it is a lower bound (`≥`), with each of them counted at its budget. The \
         figures plot the share of seeds that reached the threshold against env steps.\n",
        100.0 * share
    );
    if has_reference {
        let _ = writeln!(
            tts,
            "Where a maze and task has one and this grid's own A2C left a seed short of \
             the threshold, the reference row is the flat A2C trained longer (`worldgraph \
             table --reference`; same validation protocol and agent, checked; the notes \
             below the table name its result set); the threshold still comes from this \
             grid's cells alone.\n"
        );
    }
    let _ = writeln!(
        tts,
        "| maze | task | threshold | configuration | reached | env steps | wall s | speed-up over A2C (steps / wall) |\n|---|---|---:|---|---:|---:|---:|---:|"
    );
    tts
}

/// The threshold of maze `m` and task `t`: `share` of the best cell's score
/// there, the highest mean over seeds of the runs' best validation scores
/// (one lucky seed does not set the bar); `None` when no cell's score is
/// positive.
fn threshold(cells: &Cells, m: &str, t: &str, share: f64) -> Option<f64> {
    let best = cells
        .iter()
        .filter(|((cm, ct, _), _)| cm == m && ct == t)
        .map(|(_, rs)| mean_std(&rs.iter().map(|r| r.best_validation).collect::<Vec<_>>()).0)
        .fold(f64::NEG_INFINITY, f64::max);
    if best <= 0.0 {
        return None;
    }
    Some(share * best)
}

/// The configurations of maze `m` and task `t` by their paper's names, with
/// their runs, in Table 1's order (any other configuration after).
fn configurations<'a>(cells: &Cells<'a>, m: &str, t: &str) -> Vec<(String, Vec<&'a RunResult>)> {
    let mut here: Vec<(String, Vec<&RunResult>)> = cells
        .iter()
        .filter(|((cm, ct, _), _)| cm == m && ct == t)
        .map(|((_, _, c), rs)| (display_config(c), rs.clone()))
        .collect();
    here.sort_by_key(|(c, _)| {
        TABLE1_CONFIGS
            .iter()
            .position(|x| display_config(x) == *c)
            .unwrap_or(usize::MAX)
    });
    here
}

/// The reference row of a maze and task: its name in the table (`None`
/// without an A2C run) and whether it is the longer A2C of `--reference`.
struct ReferenceRow {
    name: Option<String>,
    longer_used: bool,
}

/// Chooses the reference row of maze `m` and task `t`: the longer A2C
/// `longer` where the grid's own A2C left a seed short of `threshold`, put
/// first in `here`, else the grid's own. Where every seed of the grid's A2C
/// reached it, its row is exact, and its wall seconds were measured beside
/// the grid's runs, not under whatever load the longer runs had. Pushes
/// onto `notes` which result set the longer A2C came from, used or not.
fn reference_row<'a>(
    cells: &Cells,
    m: &str,
    t: &str,
    threshold: f64,
    longer: Option<&'a (String, Vec<RunResult>)>,
    here: &mut Vec<(String, Vec<&'a RunResult>)>,
    notes: &mut Vec<String>,
) -> ReferenceRow {
    let grid_a2c = cells.get(&(m.to_string(), t.to_string(), "a2c".to_string()));
    let grid_a2c_reached = grid_a2c.is_some_and(|g| Times::of(g, threshold).all_reached());
    // Whether the longer runs are the grid's A2C runs continued.
    let repeat_note = |rs: &[RunResult]| {
        grid_a2c.map_or(String::new(), |g| {
            let (same, both) = repeats(rs, g);
            format!(
                "; its first {} env steps repeat this grid's A2C run of the same seed at \
                 every validation, to the last digit, on {same} of the {both} seeds both ran",
                g.iter().map(|r| r.env_steps).max().unwrap_or(0)
            )
        })
    };
    let longer_used = longer.is_some() && !grid_a2c_reached;
    let name = match longer {
        Some((dir, rs)) if longer_used => {
            let steps = rs.iter().map(|r| r.env_steps).max().unwrap_or(0);
            let name = format!("A2C, {:.2}M env steps (reference)", steps as f64 / 1e6);
            notes.push(format!(
                "{m} {t}: the reference is `{dir}`{}.",
                repeat_note(rs)
            ));
            here.insert(0, (name.clone(), rs.iter().collect()));
            Some(name)
        }
        unused => {
            if let Some((dir, rs)) = unused {
                notes.push(format!(
                    "{m} {t}: every seed of this grid's own A2C reached the threshold \
                     within the grid's budget, so its row is the reference, not the longer \
                     A2C `{dir}`{}.",
                    repeat_note(rs)
                ));
            }
            grid_a2c.map(|_| display_config("a2c"))
        }
    };
    ReferenceRow { name, longer_used }
}

/// Writes the rows of maze `m` and task `t` into `tts`, one per
/// configuration of `here`: how many seeds reached `threshold`, their mean
/// time, the speed-up over the row named `reference`. Returns each row's
/// share of seeds at the threshold, for the figure.
fn rows(
    tts: &mut String,
    m: &str,
    t: &str,
    threshold: f64,
    here: &[(String, Vec<&RunResult>)],
    reference: Option<&String>,
) -> Vec<Series> {
    let reference_times = reference.map(|name| {
        let rs = &here.iter().find(|(c, _)| c == name).expect("inserted").1;
        Times::of(rs, threshold)
    });
    let mut reach_series = Vec::new();
    for (c, rs) in here {
        let times = Times::of(rs, threshold);
        let reached = times.reached();
        let is_reference = reference == Some(c);
        let speed = match &reference_times {
            _ if is_reference => "1 (reference)".to_string(),
            Some(a) => speed_up(a, &times).unwrap_or_else(|| "—".to_string()),
            None => "— (no A2C run)".to_string(),
        };
        let (steps, wall) = if reached.is_empty() {
            ("—".to_string(), "—".to_string())
        } else {
            let (sm, ss) = mean_std(&reached.iter().map(|x| x.0 as f64).collect::<Vec<_>>());
            let (wm, ws) = mean_std(&reached.iter().map(|x| x.1).collect::<Vec<_>>());
            (format!("{sm:.0} ± {ss:.0}"), format!("{wm:.0} ± {ws:.0}"))
        };
        let _ = writeln!(
            tts,
            "| {m} | {t} | {threshold:.3} | {c} | {}/{} | {steps} | {wall} | {speed} |",
            reached.len(),
            rs.len()
        );
        reach_series.push(Series {
            name: c.clone(),
            points: reach_share(rs, &reached),
        });
    }
    reach_series
}

/// Saves the reach-share figure of maze `m` and task `t` into `figures`:
/// the share of each configuration's seeds at `threshold` against env
/// steps. When the longer A2C leads the series (`longer_used`), it is moved
/// last, so that each configuration keeps its colour of the other charts;
/// the reference takes the palette's eleventh.
fn reach_chart(
    figures: &Path,
    m: &str,
    t: &str,
    threshold: f64,
    mut reach_series: Vec<Series>,
    longer_used: bool,
) -> anyhow::Result<()> {
    if longer_used {
        reach_series.rotate_left(1);
    }
    let file = format!("time-to-score-{m}-{t}.png");
    LineChart {
        title: format!("{m} {t}: seeds at the threshold {threshold:.2}"),
        x_label: "env steps".into(),
        y_label: "share of seeds".into(),
        series: reach_series,
        x_scale: XScale::Linear,
    }
    .render(900, 520)
    .save_png(&figures.join(&file))?;
    Ok(())
}

/// The share of `rs`' seeds at the threshold against env steps, a step
/// line: the share holds until the next validation.
fn reach_share(rs: &[&RunResult], reached: &[(u64, f64)]) -> Vec<(f64, f64)> {
    let mut xs: Vec<u64> = rs
        .iter()
        .flat_map(|r| r.validation_curve.iter().map(|p| p.env_steps))
        .collect();
    xs.sort_unstable();
    xs.dedup();
    let mut points = Vec::new();
    for &x in &xs {
        let k = reached.iter().filter(|r| r.0 <= x).count();
        let y = k as f64 / rs.len() as f64;
        if let Some(&(_, prev)) = points.last() {
            points.push((x as f64, prev));
        }
        points.push((x as f64, y));
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reached(steps: u64, wall: f64) -> Time {
        Time::Reached { steps, wall }
    }

    fn censored(steps: u64, wall: f64) -> Time {
        Time::Censored { steps, wall }
    }

    #[test]
    fn speed_up_is_exact_when_every_seed_reached_and_a_bound_when_a2c_did_not() {
        let fast = Times(vec![reached(1_000, 10.0), reached(2_000, 30.0)]);
        // Every A2C seed reached it: the ratio of the two means.
        let a2c = Times(vec![reached(3_000, 40.0), reached(6_000, 80.0)]);
        assert_eq!(speed_up(&a2c, &fast).unwrap(), "3.00× / 3.00×");
        // One A2C seed ran out its 9,000-step budget (wall 100 s at its last
        // validation): counted there, A2C's mean is at least 6,000 steps and
        // 70 s, so the speed-up is at least 4× and 3.5×.
        let a2c = Times(vec![reached(3_000, 40.0), censored(9_000, 100.0)]);
        assert_eq!(speed_up(&a2c, &fast).unwrap(), "≥ 4.00× / ≥ 3.50×");
        // A configuration with a seed that did not reach it has no bound.
        let slow = Times(vec![reached(1_000, 10.0), censored(9_000, 90.0)]);
        assert_eq!(speed_up(&a2c, &slow), None);
        assert_eq!(speed_up(&Times(vec![]), &fast), None);
    }
}
