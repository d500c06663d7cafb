//! The paper's Tables 1 and 2 (section 5): their rows and columns in the
//! paper's order and the figures the paper reports, beside which `table`
//! prints the measured ones.

/// Table 1's rows, in the paper's order.
pub const TABLE1_CONFIGS: [&str; 10] = [
    "a2c",
    "fn",
    "fn-init",
    "wn-all-init",
    "wn-random-init",
    "wn-pivotal-init",
    "wn-random-trav",
    "wn-pivotal-trav",
    "wn-random-trav-init",
    "wn-pivotal-trav-init",
];

/// Table 1's tasks.
pub const TABLE1_TASKS: [&str; 3] = ["multigoal", "multigoal-sparse", "multigoal-stochastic"];

/// Every task in the order the tables list them: Table 1's, then Door-Key
/// (Table 2).
pub(super) const TASKS: [&str; 4] = [TABLE1_TASKS[0], TABLE1_TASKS[1], TABLE1_TASKS[2], "doorkey"];

/// A name's place in `names` (after all of them if absent): the sort key
/// of mazes, tasks and configurations in the tables.
pub(super) fn rank(names: &[&str], x: &str) -> usize {
    names.iter().position(|n| *n == x).unwrap_or(usize::MAX)
}

/// Table 2's columns, in the paper's order.
pub const TABLE2_CONFIGS: [&str; 7] = [
    "wn-all-init",
    "wn-random-init",
    "wn-pivotal-init",
    "wn-random-trav",
    "wn-pivotal-trav",
    "wn-random-trav-init",
    "wn-pivotal-trav-init",
];

pub(super) const MAZES: [&str; 3] = ["small", "medium", "large"];

/// The paper's Table 1 (mean reward after 100k training iterations; `None`
/// is "Fail"): rows [`TABLE1_CONFIGS`], columns task-major over
/// [`TABLE1_TASKS`] × small, medium, large.
pub(super) const PAPER_TABLE1: [[Option<f64>; 9]; 10] = {
    const F: Option<f64> = None;
    const fn v(x: f64) -> Option<f64> {
        Some(x)
    }
    [
        [v(2.04), F, F, v(-0.10), F, F, v(1.38), F, F],
        [F, F, F, v(0.19), F, F, F, F, F],
        [v(2.93), F, F, F, F, F, v(1.93), F, F],
        [v(4.73), v(4.71), F, v(0.32), F, F, v(2.59), v(1.62), F],
        [v(3.67), v(4.72), F, v(0.36), F, F, v(2.82), F, F],
        [v(5.25), v(5.15), F, v(0.39), F, F, v(3.06), v(2.99), F],
        [
            v(3.85),
            v(2.59),
            v(1.65),
            v(0.17),
            v(0.19),
            v(0.20),
            F,
            v(1.67),
            F,
        ],
        [
            v(3.92),
            v(2.56),
            v(2.18),
            v(0.24),
            v(0.20),
            v(0.16),
            F,
            v(2.42),
            v(1.05),
        ],
        [
            v(4.16),
            v(3.29),
            v(2.30),
            v(0.25),
            v(0.24),
            v(0.19),
            v(2.72),
            v(2.42),
            v(1.93),
        ],
        [
            v(5.05),
            v(3.00),
            v(2.72),
            v(0.42),
            v(0.25),
            v(0.26),
            v(2.92),
            v(2.62),
            v(1.79),
        ],
    ]
};

/// The paper's Table 2 (Door-Key success rate in %, mean and std; `None`
/// is "Fail"): rows small, medium, large; columns [`TABLE2_CONFIGS`].
pub(super) const PAPER_TABLE2: [[Option<(f64, f64)>; 7]; 3] = {
    const F: Option<(f64, f64)> = None;
    const fn v(m: f64, s: f64) -> Option<(f64, f64)> {
        Some((m, s))
    }
    [
        [
            v(94., 5.),
            v(97., 2.),
            v(99., 0.),
            F,
            v(37., 15.),
            v(76., 14.),
            v(92., 2.),
        ],
        [
            v(25., 15.),
            v(1., 1.),
            v(56., 2.),
            F,
            F,
            v(79., 11.),
            v(76., 6.),
        ],
        [F, F, F, F, F, v(27., 40.), v(26., 19.)],
    ]
};

/// The paper's budget: 100k training iterations of 32 agents.
pub(super) const PAPER_ITERATIONS: u64 = 100_000;

/// The paper's Table 1 figure of a cell (`Fail` where it failed, `—`
/// where the paper has no such cell).
pub(super) fn paper1(config: &str, task: &str, maze: &str) -> String {
    let r = TABLE1_CONFIGS.iter().position(|c| *c == config);
    let t = TABLE1_TASKS.iter().position(|c| *c == task);
    let m = MAZES.iter().position(|c| *c == maze);
    match (r, t, m) {
        (Some(r), Some(t), Some(m)) => match PAPER_TABLE1[r][t * 3 + m] {
            Some(v) => format!("{v:.2}"),
            None => "Fail".to_string(),
        },
        _ => "—".to_string(),
    }
}

/// The paper's Table 2 success rate of a cell, `mean ± std` % ("not
/// reported" for the flat A2C, which the paper leaves out of Table 2).
pub(super) fn paper2(config: &str, maze: &str) -> String {
    if config == "a2c" {
        return "not reported".to_string();
    }
    let c = TABLE2_CONFIGS.iter().position(|x| *x == config);
    let m = MAZES.iter().position(|x| *x == maze);
    match (c, m) {
        (Some(c), Some(m)) => match PAPER_TABLE2[m][c] {
            Some((v, s)) => format!("{v:.0} ± {s:.0}"),
            None => "Fail".to_string(),
        },
        _ => "—".to_string(),
    }
}
