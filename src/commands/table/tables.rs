//! The paper's Tables 1 and 2 (section 5) as the README `table` writes
//! them: each measured cell (mean ± std over the training seeds) beside the
//! paper's value, each maze labelled with its budget.

use std::fmt::Write as _;

use crate::results::RunResult;

use super::budgets::budget_label;
use super::paper::{TABLE1_CONFIGS, TABLE1_TASKS, TABLE2_CONFIGS, paper1, paper2};
use super::{Cells, display_config, mean_std};

/// A cell: mean ± std of the test scores (×`scale`), "Fail" when every
/// seed failed by the paper's rule, the seed count when not the grid's 3
/// and how many seeds failed.
fn cell_text(runs: Option<&Vec<&RunResult>>, scale: f64, digits: usize) -> String {
    let Some(runs) = runs.filter(|r| !r.is_empty()) else {
        return "—".to_string();
    };
    let fails = runs.iter().filter(|r| r.failed()).count();
    if fails == runs.len() {
        return if runs.len() == 3 {
            "Fail".to_string()
        } else {
            format!("Fail (n={})", runs.len())
        };
    }
    let scores: Vec<f64> = runs.iter().map(|r| r.test_score * scale).collect();
    let (m, s) = mean_std(&scores);
    let mut t = format!("{m:.digits$} ± {s:.digits$}");
    if runs.len() != 3 {
        let _ = write!(t, " (n={})", runs.len());
    }
    if fails > 0 {
        let _ = write!(t, " ({fails} fail)");
    }
    t
}

/// Table 1 (MultiGoal, MultiGoal-Sparse, MultiGoal-Stochastic; mean test
/// reward): one table per task that ran, a row per configuration in the
/// paper's order, a column per maze of `mazes`; empty when no task of
/// Table 1 ran.
pub(super) fn table1(runs: &[RunResult], cells: &Cells, mazes: &[&str]) -> String {
    let mut md = String::new();
    let t1_tasks: Vec<&str> = TABLE1_TASKS
        .iter()
        .copied()
        .filter(|t| runs.iter().any(|r| r.task == *t))
        .collect();
    if t1_tasks.is_empty() {
        return md;
    }
    let _ = writeln!(
        md,
        "## Table 1: MultiGoal, MultiGoal-Sparse, MultiGoal-Stochastic (mean test reward)\n"
    );
    for t in &t1_tasks {
        let _ = writeln!(md, "### {t}\n");
        let mut head = "| configuration |".to_string();
        let mut rule = "|---|".to_string();
        for m in mazes {
            let _ = write!(head, " {} | paper |", budget_label(runs, m));
            rule.push_str("---:|---:|");
        }
        let _ = writeln!(md, "{head}\n{rule}");
        for c in TABLE1_CONFIGS {
            let mut line = format!("| {} |", display_config(c));
            for m in mazes {
                let k = (m.to_string(), t.to_string(), c.to_string());
                let _ = write!(
                    line,
                    " {} | {} |",
                    cell_text(cells.get(&k), 1.0, 3),
                    paper1(c, t, m)
                );
            }
            let _ = writeln!(md, "{line}");
        }
        let _ = writeln!(md);
    }
    md
}

/// Table 2 (Door-Key; test success rate in %): a row per maze of `mazes`,
/// a column per configuration in the paper's order; empty when Door-Key
/// did not run.
pub(super) fn table2(runs: &[RunResult], cells: &Cells, mazes: &[&str]) -> String {
    let mut md = String::new();
    if !runs.iter().any(|r| r.task == "doorkey") {
        return md;
    }
    let _ = writeln!(md, "## Table 2: Door-Key (test success rate, %)\n");
    // The flat A2C, which the paper omits from Table 2, leads the
    // columns when it was run.
    let a2c = runs
        .iter()
        .any(|r| r.task == "doorkey" && r.config == "a2c");
    let columns: Vec<&str> = a2c
        .then_some("a2c")
        .into_iter()
        .chain(TABLE2_CONFIGS)
        .collect();
    let mut head = "| maze |".to_string();
    let mut rule = "|---|".to_string();
    for &c in &columns {
        let _ = write!(head, " {} | paper |", display_config(c));
        rule.push_str("---:|---:|");
    }
    let _ = writeln!(md, "{head}\n{rule}");
    for m in mazes {
        let mut line = format!("| {} |", budget_label(runs, m));
        for &c in &columns {
            let k = (m.to_string(), "doorkey".to_string(), c.to_string());
            let _ = write!(
                line,
                " {} | {} |",
                cell_text(cells.get(&k), 100.0, 0),
                paper2(c, m)
            );
        }
        let _ = writeln!(md, "{line}");
    }
    let _ = writeln!(md);
    md
}
