//! The README's world graph section: each discovery of the result set
//! (stage 1, section 3) with what it found against the maze's structure
//! and against random cells, as `discover` measured it.

use std::fmt::Write as _;

use crate::results::DiscoverResult;

/// The "World graph discoveries" section: one row per discovery summary
/// (maze, seed): rounds, pivotal states `V_p`, `π_g`'s greedy success on
/// goals ten random moves away, the passages and rooms holding a pivotal
/// state (random cells as many as `V_p` in brackets), the route stretch
/// through the graph (over `V_rand` in brackets), env steps, wall time and
/// commit. A measure an older summary lacks is `—`. Empty without any.
pub(super) fn section(discoveries: &[DiscoverResult]) -> String {
    if discoveries.is_empty() {
        return String::new();
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## World graph discoveries\n\n\
         Stage 1 (section 3) as `discover` measured it: `π_g` is its greedy success on goals \
         ten random moves away; passages and rooms are the shares of the maze's passages with \
         a pivotal state on or next to them and of its rooms holding one, with random cells \
         as many as `V_p` in brackets (the chance level); route stretch is the route's length \
         through the world graph over the shortest path (over `V_rand` graphs in brackets).\n\n\
         | maze | seed | rounds | pivotal states | `π_g` success | passages (random) | rooms (random) | route stretch (random) | env steps | wall s | commit |\n\
         |---|---:|---:|---:|---:|---|---|---|---:|---:|---|"
    );
    for d in discoveries {
        let s = &d.summary;
        let num = |k: &str| s.get(k).and_then(serde_json::Value::as_f64);
        let fmt =
            |k: &str, digits: usize| num(k).map_or("—".to_string(), |v| format!("{v:.digits$}"));
        let pair = |k: &str, digits: usize| {
            format!(
                "{} ({})",
                fmt(k, digits),
                fmt(&format!("{k}_random"), digits)
            )
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | `{}` |",
            d.spec.maze,
            d.spec.seed,
            fmt("rounds", 0),
            fmt("pivotal_states", 0),
            fmt("gcp_success_within_10", 3),
            pair("passage_share", 2),
            pair("room_share", 2),
            pair("route_stretch", 3),
            fmt("env_steps", 0),
            fmt("wall_seconds", 0),
            &d.commit[..d.commit.len().min(12)],
        );
    }
    let _ = writeln!(md);
    md
}
