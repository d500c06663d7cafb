//! HDR latency histograms of the hot loops (README.md, "The pipeline").
//!
//! Every process records its performance-critical intervals in nanoseconds
//! into named [`hdrhistogram::Histogram`]s. Recording is a few nanoseconds
//! and allocates nothing. At exit (and on request) a process prints a
//! percentile table, writes one HdrHistogram *percentile distribution* file
//! per histogram (`<role>.<name>.hgrm`, values in microseconds, the format
//! of HdrHistogram's `outputPercentileDistribution`, readable by the usual
//! plotters) and a PNG of all its histograms' percentile curves.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hdrhistogram::Histogram;

use crate::chart::{LineChart, Series, XScale};

/// Highest trackable value: 60 s in ns; larger values are clamped.
const MAX_NS: u64 = 60_000_000_000;

/// The named histograms of one process.
#[derive(Debug, Clone)]
pub struct Latencies {
    role: String,
    hists: BTreeMap<String, Histogram<u64>>,
}

/// A histogram resolved once ahead of the hot loop: recording through it
/// skips the name lookup (a string comparison per node of the map, which
/// cost more than the recording itself in the sim's per-sample loop).
#[derive(Debug, Clone)]
pub struct Recorder {
    hist: Histogram<u64>,
}

impl Recorder {
    /// An empty histogram with the bounds of [`Latencies`].
    pub fn new() -> Recorder {
        Recorder { hist: new_hist() }
    }

    /// Records `ns` nanoseconds (clamped to [1 ns, 60 s]).
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.hist.saturating_record(ns.clamp(1, MAX_NS));
    }

    /// Percentile in microseconds (NaN when empty).
    pub fn percentile_us(&self, p: f64) -> f64 {
        if self.hist.is_empty() {
            f64::NAN
        } else {
            self.hist.value_at_percentile(p) as f64 / 1e3
        }
    }

    /// Clears the histogram.
    pub fn reset(&mut self) {
        self.hist.reset();
    }

    /// Adds `other`'s counts.
    pub fn absorb(&mut self, other: &Recorder) {
        // Same bounds on both sides, so adding cannot fail.
        let _ = self.hist.add(&other.hist);
    }
}

impl Default for Recorder {
    fn default() -> Self {
        Recorder::new()
    }
}

/// The percentiles every table reports.
pub const PERCENTILES: [f64; 4] = [50.0, 90.0, 99.0, 99.9];

impl Latencies {
    /// Empty histograms for process `role` (e.g. "sim").
    pub fn new(role: &str) -> Latencies {
        Latencies {
            role: role.to_string(),
            hists: BTreeMap::new(),
        }
    }

    /// Registers histogram `name` ahead of the hot loop, so recording never allocates.
    pub fn register(&mut self, name: &str) {
        self.hists.entry(name.to_string()).or_insert_with(new_hist);
    }

    /// Records `ns` nanoseconds into histogram `name` (clamped to [1 ns, 60 s]).
    #[inline]
    pub fn record(&mut self, name: &str, ns: u64) {
        let h = match self.hists.get_mut(name) {
            Some(h) => h,
            None => self.hists.entry(name.to_string()).or_insert_with(new_hist),
        };
        h.saturating_record(ns.clamp(1, MAX_NS));
    }

    /// Percentile of `name` in microseconds (NaN when empty or unknown).
    pub fn percentile_us(&self, name: &str, p: f64) -> f64 {
        match self.hists.get(name) {
            Some(h) if !h.is_empty() => h.value_at_percentile(p) as f64 / 1e3,
            _ => f64::NAN,
        }
    }

    /// Adds `recorder`'s counts into histogram `name` (e.g. an interval's
    /// histogram into the whole run's, off the hot path).
    pub fn absorb(&mut self, name: &str, recorder: &Recorder) {
        let h = self.hists.entry(name.to_string()).or_insert_with(new_hist);
        // Same bounds on both sides, so adding cannot fail.
        let _ = h.add(&recorder.hist);
    }

    /// Clears every histogram (keeps the names).
    pub fn reset(&mut self) {
        for h in self.hists.values_mut() {
            h.reset();
        }
    }

    /// The percentile table: one row per histogram, columns count, p50, p90,
    /// p99, p99.9, max (µs).
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<26} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
            format!("{} latency (µs)", self.role),
            "count",
            "p50",
            "p90",
            "p99",
            "p99.9",
            "max"
        );
        for (name, h) in &self.hists {
            if h.is_empty() {
                let _ = writeln!(s, "{name:<26} {:>10}", 0);
                continue;
            }
            let _ = write!(s, "{name:<26} {:>10}", h.len());
            for p in PERCENTILES {
                let _ = write!(s, " {:>10.2}", h.value_at_percentile(p) as f64 / 1e3);
            }
            let _ = writeln!(s, " {:>10.2}", h.max() as f64 / 1e3);
        }
        s
    }

    /// Writes the `.hgrm` files and the PNG plot into `dir`; returns the files written.
    pub fn write_reports(&self, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
        let mut written = Vec::new();
        let mut series = Vec::new();
        for (name, h) in &self.hists {
            if h.is_empty() {
                continue;
            }
            let path = dir.join(format!("{}.{}.hgrm", self.role, name));
            sim::atomic_file::write_atomic(&path, percentile_distribution(h).as_bytes())?;
            written.push(path);
            let points = h
                .iter_quantiles(5)
                .map(|v| {
                    (
                        v.quantile_iterated_to() * 100.0,
                        v.value_iterated_to() as f64 / 1e3,
                    )
                })
                .filter(|p| p.0 < 99.9999)
                .collect();
            series.push(Series {
                name: name.clone(),
                points,
            });
        }
        if !series.is_empty() {
            let chart = LineChart {
                title: format!("{} latency by percentile", self.role),
                x_label: "percentile".into(),
                y_label: "latency (us)".into(),
                series,
                x_scale: XScale::PercentileTail,
            };
            let path = dir.join(format!("{}.latency.png", self.role));
            chart.render(900, 520).save_png(&path)?;
            written.push(path);
        }
        Ok(written)
    }
}

fn new_hist() -> Histogram<u64> {
    Histogram::new_with_bounds(1, MAX_NS, 3).expect("invariant: static histogram bounds are valid")
}

/// HdrHistogram's percentile distribution text (values in µs).
pub fn percentile_distribution(h: &Histogram<u64>) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:>12} {:>14} {:>10} {:>14}\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    );
    let mut total = 0u64;
    for v in h.iter_quantiles(5) {
        total += v.count_since_last_iteration();
        let q = v.quantile_iterated_to();
        let inv = if q < 1.0 {
            format!("{:>14.2}", 1.0 / (1.0 - q))
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "{:>12.3} {:>14.12} {:>10} {}",
            v.value_iterated_to() as f64 / 1e3,
            q,
            total,
            inv
        );
    }
    let _ = writeln!(
        s,
        "#[Mean    = {:>12.3}, StdDeviation   = {:>12.3}]",
        h.mean() / 1e3,
        h.stdev() / 1e3
    );
    let _ = writeln!(
        s,
        "#[Max     = {:>12.3}, Total count    = {:>12}]",
        h.max() as f64 / 1e3,
        h.len()
    );
    let _ = writeln!(
        s,
        "#[Buckets = {:>12}, SubBuckets     = {:>12}]",
        h.buckets(),
        h.distinct_values()
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_and_reports() {
        let mut l = Latencies::new("test");
        for i in 1..=1000u64 {
            l.record("loop", i * 1000);
        }
        assert!((l.percentile_us("loop", 50.0) - 500.0).abs() < 2.0);
        assert!((l.percentile_us("loop", 99.0) - 990.0).abs() < 2.0);
        let table = l.table();
        assert!(table.contains("loop") && table.contains("p99.9"), "{table}");
        let dir = tempfile::tempdir().unwrap();
        let files = l.write_reports(dir.path()).unwrap();
        assert_eq!(files.len(), 2);
        let hgrm = std::fs::read_to_string(&files[0]).unwrap();
        assert!(
            hgrm.contains("Percentile") && hgrm.contains("Total count    =         1000"),
            "{hgrm}"
        );
    }
}
