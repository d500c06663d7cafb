//! The validation-curve sections of the README `table` writes: the
//! comparisons of the paper's Figure 4 (section 5), then every
//! configuration's curve against env steps and against wall seconds, each
//! the mean over seeds with a band of ± one sample std.

use std::fmt::Write as _;
use std::path::Path;

use crate::chart::{Band, LineChart, XScale, band_chart};
use crate::results::RunResult;

use super::paper::TABLE1_CONFIGS;
use super::{Cells, display_config, mean_std};

/// The comparisons of the Figure 4 curves: file suffix, title, cells.
const FIGURE4: [(&str, &str, &[&str]); 4] = [
    (
        "init",
        "V_p against V_rand, π_g init",
        &["wn-random-init", "wn-pivotal-init"],
    ),
    (
        "trav",
        "V_p against V_rand, traversal",
        &["wn-random-trav", "wn-pivotal-trav"],
    ),
    (
        "trav-init",
        "V_p against V_rand, traversal + π_g init",
        &["wn-random-trav-init", "wn-pivotal-trav-init"],
    ),
    (
        "pi-g-init",
        "π_g init against none",
        &["fn", "fn-init", "wn-pivotal-trav", "wn-pivotal-trav-init"],
    ),
];

/// The section of the paper's Figure 4: per maze and task of `pairs`, one
/// chart per comparison of [`FIGURE4`] with any of its cells run, saved
/// into `figures` and linked as `fig_link`.
pub(super) fn figure4(
    cells: &Cells,
    pairs: &[(String, String)],
    figures: &Path,
    fig_link: &str,
) -> anyhow::Result<String> {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## Validation curves (the paper's Figure 4)\n\n\
         Validation score against env steps, the mean over seeds with a band of ± one (sample) \
         std: `V_p` against `V_rand` with `π_g` initialisation, with traversal, and with both; \
         then `π_g` initialisation against none.\n"
    );
    for (m, t) in pairs {
        let mut links = Vec::new();
        for (what, title, configs) in FIGURE4 {
            let bands: Vec<Band> = configs
                .iter()
                .filter_map(|c| {
                    cells
                        .get(&(m.clone(), t.clone(), c.to_string()))
                        .map(|rs| mean_band(&display_config(c), rs))
                })
                .collect();
            if bands.is_empty() {
                continue;
            }
            let file = format!("fig4-{m}-{t}-{what}.png");
            let chart = LineChart {
                title: format!("{m} {t}: {title}"),
                x_label: "env steps".into(),
                y_label: "validation score".into(),
                series: Vec::new(),
                x_scale: XScale::Linear,
            };
            band_chart(&chart, &bands, 1000, 440).save_png(&figures.join(&file))?;
            links.push(format!("![{m} {t}: {title}]({fig_link}/{file})"));
        }
        if !links.is_empty() {
            let _ = writeln!(md, "### {m}, {t}\n\n{}\n", links.join("\n"));
        }
    }
    Ok(md)
}

/// The section of every configuration's learning curve: per maze and task
/// of `pairs`, two charts of all its configurations (Table 1's order, then
/// any other), against env steps and against training wall seconds, saved
/// into `figures` and linked as `fig_link`.
pub(super) fn every_configuration(
    cells: &Cells,
    pairs: &[(String, String)],
    figures: &Path,
    fig_link: &str,
) -> anyhow::Result<String> {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "## Learning curves of every configuration\n\n\
         Validation score, the mean over seeds with a band of ± one (sample) std, against env \
         steps and against training wall seconds (the seeds' mean at each validation).\n"
    );
    for (m, t) in pairs {
        // Table 1's order, then any other configuration of the cell.
        let mut configs: Vec<String> = TABLE1_CONFIGS.iter().map(|c| c.to_string()).collect();
        for (mm, tt, c) in cells.keys() {
            if (mm, tt) == (m, t) && !configs.contains(c) {
                configs.push(c.clone());
            }
        }
        configs.retain(|c| cells.contains_key(&(m.clone(), t.clone(), c.clone())));
        if configs.is_empty() {
            continue;
        }
        let mut links = Vec::new();
        for (axis, label) in [("env-steps", "env steps"), ("wall-seconds", "wall seconds")] {
            let bands: Vec<Band> = configs
                .iter()
                .map(|c| {
                    let rs = &cells[&(m.clone(), t.clone(), c.to_string())];
                    let name = display_config(c);
                    match axis {
                        "env-steps" => mean_band(&name, rs),
                        _ => mean_band_over(&name, rs, |p| p.wall_seconds),
                    }
                })
                .collect();
            let file = format!("curves-{m}-{t}-{axis}.png");
            let chart = LineChart {
                title: format!("{m} {t}: validation score against {label}"),
                x_label: label.into(),
                y_label: "validation score".into(),
                series: Vec::new(),
                x_scale: XScale::Linear,
            };
            band_chart(&chart, &bands, 1000, 480).save_png(&figures.join(&file))?;
            links.push(format!("![{m} {t}: against {label}]({fig_link}/{file})"));
        }
        let _ = writeln!(md, "### {m}, {t}\n\n{}\n", links.join("\n"));
    }
    Ok(md)
}

/// The mean validation curve of a cell's seeds with ± one sample std, at
/// the env steps every seed reached.
fn mean_band(name: &str, rs: &[&RunResult]) -> Band {
    mean_band_over(name, rs, |p| p.env_steps as f64)
}

/// The mean ± std band of `rs`' validation curves, the i-th points of the
/// runs matched, at x = the runs' mean of `x` at that point (env steps are
/// the same in every run; wall seconds differ, so they are averaged).
fn mean_band_over(
    name: &str,
    rs: &[&RunResult],
    x: impl Fn(&crate::results::CurvePoint) -> f64,
) -> Band {
    let len = rs
        .iter()
        .map(|r| r.validation_curve.len())
        .min()
        .unwrap_or(0);
    Band {
        name: format!("{name} (n={})", rs.len()),
        points: (0..len)
            .map(|i| {
                let ys: Vec<f64> = rs.iter().map(|r| r.validation_curve[i].score).collect();
                let xs: Vec<f64> = rs.iter().map(|r| x(&r.validation_curve[i])).collect();
                let (m, s) = mean_std(&ys);
                (mean_std(&xs).0, m, m - s, m + s)
            })
            .collect(),
    }
}
