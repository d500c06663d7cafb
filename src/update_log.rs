//! The per-update record of a `train` run: `updates.csv` (one row per
//! update) and the same figures as TensorBoard scalars under
//! `tensorboard/`, tagged as CleanRL tags them (`charts/episodic_return`,
//! `losses/value_loss`, `charts/SPS`, ...; the step is the env step), so
//! a user can watch runs with `tensorboard --logdir runs/`.
//!
//! A run resumes from its last checkpoint, so the log does too: opening it
//! keeps the rows up to the checkpoint's env steps and drops the rest (the
//! updates a killed process made after it), and rewrites the TensorBoard
//! events from the kept rows. A resumed run's log is therefore the log of
//! an uninterrupted one, row for row.

use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use sim::atomic_file::write_atomic;
use syntaxdot_summary::SummaryWriter;

/// The log's CSV file in the run directory.
pub const UPDATES_CSV: &str = "updates.csv";
/// The TensorBoard directory in the run directory.
pub const TENSORBOARD_DIR: &str = "tensorboard";

/// One update's figures.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UpdateRow {
    /// Updates done (1 for the first).
    pub update: u64,
    /// Env steps done after it.
    pub env_steps: u64,
    /// Training wall seconds by then (validation excluded).
    pub wall_seconds: f64,
    /// Training episodes that ended during the update.
    pub episodes: usize,
    /// Their mean return (`NaN` when none ended).
    pub episodic_return: f64,
    /// The Worker's (or the baseline's) policy loss.
    pub policy_loss: f64,
    /// Its value loss.
    pub value_loss: f64,
    /// Its policy entropy.
    pub entropy: f64,
    /// The Manager's policy loss (0 for A2C).
    pub manager_policy_loss: f64,
    /// The Manager's value loss.
    pub manager_value_loss: f64,
    /// The Manager's policy entropy.
    pub manager_entropy: f64,
    /// Manager intervals that ended during the update.
    pub intervals: usize,
    /// Share of those in which the Worker reached its goal.
    pub goals_reached: f64,
    /// Share of the update's env steps taken by graph traversal.
    pub traversal_share: f64,
    /// Env steps per second of the update.
    pub sps: f64,
    /// Share of the training episodes that ended during the update by
    /// reaching the exit (`NaN` when none ended).
    pub exit_share: f64,
    /// Share of the Manager's decisions during the update whose narrow goal
    /// `g_n` is the exit (0 for A2C).
    pub exit_goal_share: f64,
    /// Share of the Manager's decisions during the update whose narrow goal
    /// `g_n` holds a ball when it is named (0 for A2C): how often the
    /// Manager points the Worker at the task's rewards.
    pub ball_goal_share: f64,
    /// Share of the training episodes that ended during the update carrying
    /// the key (Door-Key; `NaN` when none ended).
    pub key_share: f64,
    /// Share of the training episodes that ended during the update in which
    /// the locked door was opened (Door-Key: also when it was closed again;
    /// `NaN` when none ended).
    pub door_share: f64,
    /// Share of the training episodes that ended during the update in which
    /// the key was picked up (Door-Key; 0 on the other tasks).
    pub key_taken_share: f64,
    /// Share of the Manager's decisions during the update that named the
    /// key as `g_w` or `g_n` (Door-Key).
    pub key_goal_share: f64,
    /// Share of the Manager's decisions during the update that named a door
    /// not yet open as `g_w` or `g_n` (Door-Key).
    pub door_goal_share: f64,
}

/// The CSV header, the fields of [`UpdateRow`] in order.
pub const HEADER: &str = "update,env_steps,wall_seconds,episodes,episodic_return,policy_loss,value_loss,entropy,manager_policy_loss,manager_value_loss,manager_entropy,intervals,goals_reached,traversal_share,sps,exit_share,exit_goal_share,ball_goal_share,key_share,door_share,key_taken_share,key_goal_share,door_goal_share";
/// Fields of a row written before the exit columns (read on resume).
const OLD_FIELDS: usize = 15;
/// Fields of a row written before the ball column (read on resume).
const EXIT_FIELDS: usize = 17;
/// Fields of a row written before the key and door columns (read on
/// resume).
const BALL_FIELDS: usize = 18;
/// Fields of a row written before the key-taken and object-goal columns
/// (read on resume).
const KEY_FIELDS: usize = 20;

impl UpdateRow {
    fn csv_line(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{},{},{:.3},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{:.6},{:.6},{:.1},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
            self.update,
            self.env_steps,
            self.wall_seconds,
            self.episodes,
            self.episodic_return,
            self.policy_loss,
            self.value_loss,
            self.entropy,
            self.manager_policy_loss,
            self.manager_value_loss,
            self.manager_entropy,
            self.intervals,
            self.goals_reached,
            self.traversal_share,
            self.sps,
            self.exit_share,
            self.exit_goal_share,
            self.ball_goal_share,
            self.key_share,
            self.door_share,
            self.key_taken_share,
            self.key_goal_share,
            self.door_goal_share
        );
        s
    }

    /// Parses one CSV line; `None` for a malformed one (a line a killed
    /// process left half written). A row of an earlier version, without the
    /// exit or ball columns, reads with them `NaN`.
    fn parse(line: &str) -> Option<UpdateRow> {
        let f: Vec<&str> = line.trim_end().split(',').collect();
        let old = f.len() == OLD_FIELDS;
        let no_ball = old || f.len() == EXIT_FIELDS;
        let no_key = no_ball || f.len() == BALL_FIELDS;
        let no_objects = no_key || f.len() == KEY_FIELDS;
        if f.len() != HEADER.split(',').count() && !no_objects {
            return None;
        }
        let x = |i: usize| f[i].parse::<f64>().ok();
        let n = |i: usize| f[i].parse::<u64>().ok();
        Some(UpdateRow {
            update: n(0)?,
            env_steps: n(1)?,
            wall_seconds: x(2)?,
            episodes: n(3)? as usize,
            episodic_return: x(4)?,
            policy_loss: x(5)?,
            value_loss: x(6)?,
            entropy: x(7)?,
            manager_policy_loss: x(8)?,
            manager_value_loss: x(9)?,
            manager_entropy: x(10)?,
            intervals: n(11)? as usize,
            goals_reached: x(12)?,
            traversal_share: x(13)?,
            sps: x(14)?,
            exit_share: if old { f64::NAN } else { x(15)? },
            exit_goal_share: if old { f64::NAN } else { x(16)? },
            ball_goal_share: if no_ball { f64::NAN } else { x(17)? },
            key_share: if no_key { f64::NAN } else { x(18)? },
            door_share: if no_key { f64::NAN } else { x(19)? },
            key_taken_share: if no_objects { f64::NAN } else { x(20)? },
            key_goal_share: if no_objects { f64::NAN } else { x(21)? },
            door_goal_share: if no_objects { f64::NAN } else { x(22)? },
        })
    }

    /// The TensorBoard scalars of the row: CleanRL's tags where CleanRL has
    /// the figure, `hrl/...` for the hierarchy's own.
    fn scalars(&self, hierarchy: bool) -> Vec<(&'static str, f64)> {
        let mut v = vec![
            ("losses/policy_loss", self.policy_loss),
            ("losses/value_loss", self.value_loss),
            ("losses/entropy", self.entropy),
            ("charts/SPS", self.sps),
        ];
        if self.episodes > 0 {
            v.push(("charts/episodic_return", self.episodic_return));
            v.push(("charts/exit_share", self.exit_share));
            v.push(("charts/key_share", self.key_share));
            v.push(("charts/door_share", self.door_share));
            v.push(("charts/key_taken_share", self.key_taken_share));
        }
        if hierarchy {
            v.extend([
                ("losses/manager_policy_loss", self.manager_policy_loss),
                ("losses/manager_value_loss", self.manager_value_loss),
                ("losses/manager_entropy", self.manager_entropy),
                ("hrl/goals_reached", self.goals_reached),
                ("hrl/traversal_share", self.traversal_share),
                ("hrl/exit_goal_share", self.exit_goal_share),
                ("hrl/ball_goal_share", self.ball_goal_share),
                ("hrl/key_goal_share", self.key_goal_share),
                ("hrl/door_goal_share", self.door_goal_share),
            ]);
        }
        v
    }
}

/// The rows of an `updates.csv` text, its header and any malformed line
/// (one a killed process left half written) left out.
fn parse_rows(text: &str) -> Vec<UpdateRow> {
    text.lines().skip(1).filter_map(UpdateRow::parse).collect()
}

/// The open log of a run (module docs).
pub struct UpdateLog {
    csv: File,
    tb: SummaryWriter<File>,
    hierarchy: bool,
    path: PathBuf,
}

impl UpdateLog {
    /// The rows of the log of the run in `dir` (a half-written last line
    /// left out).
    pub fn read(dir: &Path) -> anyhow::Result<Vec<UpdateRow>> {
        let path = dir.join(UPDATES_CSV);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        Ok(parse_rows(&text))
    }

    /// Opens the log of the run in `dir`, keeping the rows up to
    /// `keep_through` env steps (the checkpoint the run resumes from; 0 for
    /// a fresh run). `hierarchy`: the Manager's figures are logged too.
    pub fn open(dir: &Path, keep_through: u64, hierarchy: bool) -> anyhow::Result<UpdateLog> {
        let path = dir.join(UPDATES_CSV);
        let kept: Vec<UpdateRow> = match std::fs::read_to_string(&path) {
            Ok(text) => parse_rows(&text)
                .into_iter()
                .filter(|r| r.env_steps <= keep_through)
                .collect(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        };
        let mut text = format!("{HEADER}\n");
        for r in &kept {
            text.push_str(&r.csv_line());
        }
        write_atomic(&path, text.as_bytes())?;
        let csv = OpenOptions::new()
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot open {}", path.display()))?;

        // The events are rewritten whole from the kept rows: one file.
        let tb_dir = dir.join(TENSORBOARD_DIR);
        if tb_dir.exists() {
            std::fs::remove_dir_all(&tb_dir)
                .with_context(|| format!("cannot clear {}", tb_dir.display()))?;
        }
        std::fs::create_dir_all(&tb_dir)
            .with_context(|| format!("cannot create {}", tb_dir.display()))?;
        let events = tb_dir.join("events.out.tfevents.worldgraph");
        let file =
            File::create(&events).with_context(|| format!("cannot create {}", events.display()))?;
        let tb = SummaryWriter::new(file)
            .with_context(|| format!("cannot write {}", events.display()))?;
        let mut log = UpdateLog {
            csv,
            tb,
            hierarchy,
            path,
        };
        for r in &kept {
            log.write_scalars(r)?;
        }
        Ok(log)
    }

    fn write_scalars(&mut self, r: &UpdateRow) -> anyhow::Result<()> {
        for (tag, v) in r.scalars(self.hierarchy) {
            self.tb
                .write_scalar(tag, r.env_steps as i64, v as f32)
                .context("cannot write the TensorBoard events")?;
        }
        Ok(())
    }

    /// Appends one update.
    pub fn push(&mut self, r: &UpdateRow) -> anyhow::Result<()> {
        self.csv
            .write_all(r.csv_line().as_bytes())
            .with_context(|| format!("cannot append to {}", self.path.display()))?;
        self.write_scalars(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(update: u64) -> UpdateRow {
        UpdateRow {
            update,
            env_steps: update * 1920,
            wall_seconds: update as f64 * 0.25,
            episodes: (update % 3) as usize,
            episodic_return: if update.is_multiple_of(3) {
                f64::NAN
            } else {
                0.5
            },
            policy_loss: -0.01,
            value_loss: 0.04,
            entropy: 1.05,
            intervals: 7,
            goals_reached: 0.25,
            sps: 7680.0,
            ..UpdateRow::default()
        }
    }

    /// The TFRecord framing TensorBoard reads: each record is a u64 length,
    /// a CRC of it, the data and a CRC of that. Returns the records' data.
    fn records(bytes: &[u8]) -> Vec<&[u8]> {
        let mut out = Vec::new();
        let mut at = 0;
        while at < bytes.len() {
            let len = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
            out.push(&bytes[at + 12..at + 12 + len]);
            at += 12 + len + 4;
        }
        assert_eq!(at, bytes.len(), "records end where the file ends");
        out
    }

    #[test]
    fn a_row_round_trips_and_a_row_of_an_earlier_version_reads_without_its_exit_figures() {
        let r = UpdateRow {
            exit_share: 0.125,
            exit_goal_share: 0.5,
            ball_goal_share: 0.25,
            key_share: 0.375,
            door_share: 0.0625,
            key_taken_share: 0.5,
            key_goal_share: 0.03125,
            door_goal_share: 0.015625,
            ..row(4)
        };
        assert_eq!(UpdateRow::parse(&r.csv_line()), Some(r));
        // The 20 fields of the version before the key-taken and object-goal
        // columns.
        let key = "4,7680,1.000,1,0.500000,-0.010000,0.040000,1.050000,0,0,0,7,0.25,0,7680.0,0.125,0.5,0.25,0.375,0.0625";
        let k = UpdateRow::parse(key).expect("a row without the object-goal columns reads");
        assert_eq!((k.key_share, k.door_share), (0.375, 0.0625));
        assert!(k.key_taken_share.is_nan() && k.door_goal_share.is_nan());
        // The 18 fields of the version before the key and door columns.
        let ball = "4,7680,1.000,1,0.500000,-0.010000,0.040000,1.050000,0,0,0,7,0.25,0,7680.0,0.125,0.5,0.25";
        let b = UpdateRow::parse(ball).expect("a row without the key column reads");
        assert_eq!(b.ball_goal_share, 0.25);
        assert!(b.key_share.is_nan() && b.door_share.is_nan());
        // The 17 fields of the version before the ball column.
        let exit =
            "4,7680,1.000,1,0.500000,-0.010000,0.040000,1.050000,0,0,0,7,0.25,0,7680.0,0.125,0.5";
        let e = UpdateRow::parse(exit).expect("a row without the ball column reads");
        assert_eq!((e.exit_share, e.exit_goal_share), (0.125, 0.5));
        assert!(e.ball_goal_share.is_nan());
        // The 15 fields an earlier version wrote, then a half-written line.
        let old = "4,7680,1.000,1,0.500000,-0.010000,0.040000,1.050000,0,0,0,7,0.25,0,7680.0";
        let o = UpdateRow::parse(old).expect("an earlier row reads");
        assert_eq!((o.update, o.env_steps, o.intervals), (4, 7680, 7));
        assert!(o.exit_share.is_nan() && o.exit_goal_share.is_nan() && o.ball_goal_share.is_nan());
        assert_eq!(UpdateRow::parse("4,7680,1.000,1,0.5"), None);
    }

    #[test]
    fn a_resumed_log_is_the_log_of_an_uninterrupted_run() {
        let whole = tempfile::tempdir().unwrap();
        let mut log = UpdateLog::open(whole.path(), 0, false).unwrap();
        for u in 1..=6 {
            log.push(&row(u)).unwrap();
        }
        drop(log);

        // Killed after update 5 with its checkpoint at update 4, and a
        // half-written line at the end.
        let cut = tempfile::tempdir().unwrap();
        let mut log = UpdateLog::open(cut.path(), 0, false).unwrap();
        for u in 1..=5 {
            log.push(&row(u)).unwrap();
        }
        drop(log);
        let mut f = OpenOptions::new()
            .append(true)
            .open(cut.path().join(UPDATES_CSV))
            .unwrap();
        f.write_all(b"6,11520,1.5").unwrap();
        drop(f);
        let mut log = UpdateLog::open(cut.path(), row(4).env_steps, false).unwrap();
        for u in 5..=6 {
            log.push(&row(u)).unwrap();
        }
        drop(log);

        let a = std::fs::read_to_string(whole.path().join(UPDATES_CSV)).unwrap();
        let b = std::fs::read_to_string(cut.path().join(UPDATES_CSV)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.lines().count(), 7);
        assert!(a.starts_with(HEADER));
        assert_eq!(UpdateRow::parse(a.lines().nth(2).unwrap()), Some(row(2)));

        // The events hold the same scalars (wall times aside): one
        // TensorBoard file, the version record, then one record per
        // scalar, with `charts/episodic_return`, `charts/exit_share`,
        // `charts/key_share`, `charts/door_share` and
        // `charts/key_taken_share` only where episodes
        // ended.
        let events = |d: &Path| {
            let files: Vec<_> = std::fs::read_dir(d.join(TENSORBOARD_DIR))
                .unwrap()
                .collect();
            assert_eq!(files.len(), 1);
            std::fs::read(files[0].as_ref().unwrap().path()).unwrap()
        };
        let (ea, eb) = (events(whole.path()), events(cut.path()));
        let (ra, rb) = (records(&ea), records(&eb));
        assert_eq!(ra.len(), rb.len());
        let with_return = (1..=6).filter(|u| u % 3 != 0).count();
        assert_eq!(ra.len(), 1 + 6 * 4 + 5 * with_return);
        let tagged = |rs: &[&[u8]], tag: &str| {
            rs.iter()
                .filter(|r| r.windows(tag.len()).any(|w| w == tag.as_bytes()))
                .count()
        };
        assert_eq!(tagged(&ra, "charts/SPS"), 6);
        assert_eq!(tagged(&rb, "charts/episodic_return"), with_return);
        assert_eq!(tagged(&rb, "charts/exit_share"), with_return);
        assert!(ra[0].windows(13).any(|w| w == b"brain.Event:2"));
    }
}
