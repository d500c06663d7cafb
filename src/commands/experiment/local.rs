//! The local runner: the grid's cells as child processes of this one
//! (`experiment GRID --cell INDEX`, [`super::cell`]), as many side by side
//! as `--jobs`, each training run once the discovery it needs is done.

use std::collections::VecDeque;
use std::process::{Child, ExitCode};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::bail;
use indicatif::ProgressBar;

use super::cells::Cells;
use super::{Job, Plan, record_finished_discoveries, score_note, start, tail};

/// Runs the selected cells that are not done (with `dry_run`, lists them).
pub(super) fn run(plan: &Plan, cells: &Cells, dry_run: bool) -> anyhow::Result<ExitCode> {
    let queue: VecDeque<usize> = cells.todo().into();
    let (trains, trains_done) = cells.trains();
    eprintln!(
        "experiment {}: {} training runs ({} done, {} to run), {} discoveries to run; {} side by side, {} libtorch thread(s) each; work in {}, results in {}",
        plan.grid.name,
        trains,
        trains_done,
        trains - trains_done,
        queue
            .iter()
            .filter(|&&i| matches!(cells.all[i], Job::Discover { .. }))
            .count(),
        plan.jobs,
        plan.threads,
        plan.work.display(),
        plan.results.display()
    );
    if dry_run {
        for &i in &queue {
            println!("{}", Plan::label(&cells.all[i]));
        }
        return Ok(ExitCode::SUCCESS);
    }
    record_finished_discoveries(plan, cells)?;
    let mut s = Scheduler {
        plan,
        all: &cells.all,
        finished: cells.done.clone(),
        bar: crate::progress::bar(queue.len() as u64, "experiment"),
        queue,
        running: Vec::new(),
        failed: Vec::new(),
        done_now: 0,
    };
    let stop = crate::shutdown::stop_flag_with_hangup()?;
    while !(s.running.is_empty() && s.queue.is_empty()) {
        if stop.load(Ordering::Relaxed) {
            s.stop_all();
            bail!(
                "stopped: {} runs finished this time; the rest resume from their checkpoints on the next start",
                s.done_now
            );
        }
        s.reap()?;
        s.launch()?;
        s.show_progress();
        std::thread::sleep(Duration::from_millis(250));
    }
    s.bar.finish_and_clear();
    eprintln!(
        "experiment {}: {} runs finished, {} failed; `worldgraph table {}` renders the tables",
        plan.grid.name,
        s.done_now,
        s.failed.len(),
        plan.results.display()
    );
    for (i, e) in &s.failed {
        eprintln!("  failed {}: {e}", Plan::label(&s.all[*i]));
    }
    Ok(if s.failed.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// The cells of one local run of a grid: waiting, running, finished and
/// failed.
struct Scheduler<'a> {
    plan: &'a Plan,
    all: &'a [Job],
    /// Per cell: done (before this run or during it).
    finished: Vec<bool>,
    /// Cells still to start, in index order.
    queue: VecDeque<usize>,
    /// Cell processes running: cell, process, start.
    running: Vec<(usize, Child, Instant)>,
    /// Cells that failed, with why.
    failed: Vec<(usize, String)>,
    /// Cells finished by this run.
    done_now: usize,
    bar: ProgressBar,
}

impl Scheduler<'_> {
    /// Collects the cell processes that ended.
    fn reap(&mut self) -> anyhow::Result<()> {
        let mut k = 0;
        while k < self.running.len() {
            let Some(status) = self.running[k].1.try_wait()? else {
                k += 1;
                continue;
            };
            let (i, _, started) = self.running.swap_remove(k);
            let job = &self.all[i];
            let log = self.plan.log_path(job);
            if status.success() {
                self.finished[i] = true;
                self.done_now += 1;
                let secs = started.elapsed().as_secs_f64();
                let note = format!(
                    "done {} ({secs:.0} s){}",
                    Plan::label(job),
                    score_note(self.plan, job)
                );
                crate::progress::note(&self.bar, &note);
            } else {
                let e = format!("{status}; the end of {}:\n{}", log.display(), tail(&log, 6));
                crate::progress::note(&self.bar, &format!("FAILED {}: {e}", Plan::label(job)));
                self.failed.push((i, e));
            }
            self.bar.inc(1);
        }
        Ok(())
    }

    /// Starts queued cells whose discovery is done, up to `--jobs` at once;
    /// a cell whose discovery failed fails with it.
    fn launch(&mut self) -> anyhow::Result<()> {
        let mut k = 0;
        while self.running.len() < self.plan.jobs && k < self.queue.len() {
            let i = self.queue[k];
            if let Job::Train { needs: Some(n), .. } = &self.all[i]
                && !self.finished[*n]
            {
                if self.failed.iter().any(|(f, _)| f == n) {
                    let why = format!("its discovery ({}) failed", Plan::label(&self.all[*n]));
                    self.failed.push((i, why));
                    self.bar.inc(1);
                    self.queue.remove(k);
                } else {
                    k += 1;
                }
                continue;
            }
            let mut cmd = crate::pipeline::worldgraph_command()?;
            cmd.args(self.plan.cell_args(self.plan.jobs))
                .arg("--cell")
                .arg(i.to_string());
            let log = self.plan.log_path(&self.all[i]);
            let child = start(cmd, &log, self.plan.threads)?;
            self.running.push((i, child, Instant::now()));
            self.queue.remove(k);
        }
        Ok(())
    }

    /// SIGTERM to every running cell (each stops its run, which resumes
    /// from its checkpoint next time), then waits for them.
    fn stop_all(&mut self) {
        for (_, child, _) in &self.running {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(child.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        for (_, child, _) in &mut self.running {
            let _ = child.wait();
        }
        self.bar.finish_and_clear();
    }

    fn show_progress(&self) {
        let names: Vec<String> = self
            .running
            .iter()
            .map(|(i, _, _)| Plan::label(&self.all[*i]))
            .collect();
        self.bar.set_message(format!(
            "done {}, running {} [{}], left {}, failed {}",
            self.done_now,
            self.running.len(),
            names.join(", "),
            self.queue.len(),
            self.failed.len()
        ));
    }
}
