//! How a process waits for its peer's next sample: spin briefly, then yield.
//!
//! Polling iceoryx2 is the fastest way to see a sample (sub-µs), but a
//! process that only spins wastes its whole time slice when the peer it waits
//! for is descheduled on the same core, which on a 2-core machine with a
//! third busy process turns µs round trips into ms. So a waiter spins for
//! [`Backoff::SPIN`], then calls `sched_yield` between polls (the peer gets
//! the core at once if it is runnable there), and past [`Backoff::YIELD`]
//! sleeps briefly between polls, so an idle pipeline costs no CPU.

use std::time::{Duration, Instant};

/// State of one wait.
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    /// Read at the first clock check, not at creation: a wait answered
    /// within the first polls (the common case) never reads the clock.
    start: Option<Instant>,
    polls: u32,
}

impl Backoff {
    /// Pure spinning for this long.
    pub const SPIN: Duration = Duration::from_micros(20);
    /// Then yielding between polls for this long, then sleeping.
    pub const YIELD: Duration = Duration::from_millis(5);
    /// Sleep between polls after [`Backoff::YIELD`].
    pub const SLEEP: Duration = Duration::from_micros(200);

    /// A wait that starts now.
    #[inline]
    pub fn new() -> Backoff {
        Backoff {
            start: None,
            polls: 0,
        }
    }

    /// Call after each empty poll.
    #[inline]
    pub fn snooze(&mut self) {
        self.polls = self.polls.wrapping_add(1);
        // Reading the clock is not free: do it every 16 polls while spinning.
        if self.polls < 64 || !self.polls.is_multiple_of(16) {
            std::hint::spin_loop();
            return;
        }
        let waited = self.start.get_or_insert_with(Instant::now).elapsed();
        if waited < Self::SPIN {
            std::hint::spin_loop();
        } else if waited < Self::YIELD {
            std::thread::yield_now();
        } else {
            std::thread::sleep(Self::SLEEP);
        }
    }

    /// Time since the wait's first clock check (after 64 polls).
    pub fn waited(&self) -> Duration {
        self.start.map_or(Duration::ZERO, |s| s.elapsed())
    }
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff::new()
    }
}
