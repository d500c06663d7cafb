//! The Worker (Shang et al. 2019, sections 4.1–4.2): a goal-conditioned
//! A2C-LSTM with `π_g`'s architecture, "rewarded if reaching `g_w` or `g_n`
//! within the horizon `c`" — by the Manager, not by the task.
//!
//! Per Worker step ([`WorkerGoal::book`]): the step penalty, plus the goal
//! reward when the agent stands on `g_n`, or on `g_w` for the first time in
//! the interval (the Feudal Worker has one goal, `g_w = g_n`). Reaching
//! `g_n` ends the Worker's goal episode and the Manager's interval, and so
//! do `c` Worker steps and the end of the environment's episode. Handing
//! over to a world-graph traversal towards `g_w` also ends the goal episode,
//! paid as reaching `g_w` (the route brings the agent there; the Worker
//! resumes at `g_w` with a fresh goal episode for `g_n`).

/// The Worker's goals in one environment's current interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkerGoal {
    /// The wide goal `g_w` (FN: the subgoal).
    pub wide: u32,
    /// The narrow goal `g_n` (FN: the subgoal).
    pub narrow: u32,
    /// `g_w` has been paid for in this interval.
    pub wide_paid: bool,
    /// Worker steps taken in this interval.
    pub steps: u32,
}

/// What one Worker step earned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkerStep {
    /// The Worker's reward.
    pub reward: f32,
    /// The Worker's goal episode ended.
    pub done: bool,
    /// The interval is over (`g_n` reached, horizon, episode end).
    pub interval_over: bool,
    /// `g_n` was reached.
    pub reached: bool,
}

impl WorkerGoal {
    /// A fresh interval with goals `(wide, narrow)`.
    pub fn new(wide: u32, narrow: u32) -> WorkerGoal {
        WorkerGoal {
            wide,
            narrow,
            wide_paid: false,
            steps: 0,
        }
    }

    /// Books one Worker step that left the agent on `cell` (`episode_ended`:
    /// the environment's episode ended with it, so its arrival cannot be
    /// judged), with horizon `horizon`, goal reward `goal` and step penalty
    /// `penalty`.
    pub fn book(
        &mut self,
        cell: u32,
        episode_ended: bool,
        horizon: u32,
        goal: f32,
        penalty: f32,
    ) -> WorkerStep {
        self.steps += 1;
        if episode_ended {
            return WorkerStep {
                reward: penalty,
                done: true,
                interval_over: true,
                reached: false,
            };
        }
        let reached = cell == self.narrow;
        let wide_now = cell == self.wide && !self.wide_paid;
        if wide_now {
            self.wide_paid = true;
        }
        let paid = reached || wide_now;
        let over = reached || self.steps >= horizon;
        WorkerStep {
            reward: penalty + if paid { goal } else { 0.0 },
            done: over,
            interval_over: over,
            reached,
        }
    }

    /// Books a hand-over to a traversal towards `g_w` on the step just
    /// booked as `step`: paid as reaching `g_w`, the goal episode ends.
    pub fn hand_over(&mut self, step: &mut WorkerStep, goal: f32) {
        if !self.wide_paid {
            step.reward += goal;
            self.wide_paid = true;
        }
        step.done = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worker_is_paid_for_g_w_or_g_n_and_for_nothing_else() {
        let (goal, penalty, c) = (1.0, -0.01, 20);
        // Wide-then-Narrow: g_w = 10, g_n = 12.
        let mut g = WorkerGoal::new(10, 12);
        let s = g.book(3, false, c, goal, penalty);
        assert_eq!((s.reward, s.done, s.interval_over), (penalty, false, false));
        let s = g.book(10, false, c, goal, penalty);
        assert_eq!(s.reward, penalty + goal, "g_w is paid");
        assert!(!s.done, "reaching g_w does not end the interval");
        let s = g.book(11, false, c, goal, penalty);
        assert_eq!(s.reward, penalty);
        let s = g.book(10, false, c, goal, penalty);
        assert_eq!(s.reward, penalty, "g_w is paid once per interval");
        let s = g.book(12, false, c, goal, penalty);
        assert_eq!(s.reward, penalty + goal, "g_n is paid");
        assert!(s.done && s.interval_over && s.reached);
        // Arriving with the episode's end earns nothing but the penalty.
        let mut g = WorkerGoal::new(10, 12);
        let s = g.book(12, true, c, goal, penalty);
        assert_eq!(s.reward, penalty);
        assert!(s.done && s.interval_over && !s.reached);
        // The horizon ends the interval unpaid.
        let mut g = WorkerGoal::new(10, 12);
        let steps: Vec<WorkerStep> = (0..c).map(|_| g.book(5, false, c, goal, penalty)).collect();
        assert!(steps[..c as usize - 1].iter().all(|s| !s.done));
        assert!(steps[c as usize - 1].interval_over);
        assert!(steps.iter().all(|s| s.reward == penalty));
        // Feudal: one goal, paid once.
        let mut g = WorkerGoal::new(7, 7);
        let s = g.book(7, false, c, goal, penalty);
        assert_eq!(s.reward, penalty + goal);
        // A hand-over pays g_w unless it was paid already.
        let mut g = WorkerGoal::new(10, 12);
        let mut s = g.book(4, false, c, goal, penalty);
        g.hand_over(&mut s, goal);
        assert_eq!(s.reward, penalty + goal);
        assert!(s.done);
        let mut s = g.book(10, false, c, goal, penalty);
        assert_eq!(s.reward, penalty, "g_w was paid at the hand-over");
        g.hand_over(&mut s, goal);
        assert_eq!(s.reward, penalty);
    }
}
