//! Sequence-number bookkeeping for a stream of batches: counts lost,
//! repeated and reordered batches from the headers' `seq` fields (what the
//! soak test reports).

/// What one received sequence number means relative to the previous ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeqEvent {
    /// The first number seen.
    First,
    /// Exactly the next number.
    InOrder,
    /// Numbers were skipped: `missing` batches lost.
    Gap {
        /// How many numbers were skipped.
        missing: u64,
    },
    /// A number at or below the last one: a repeat or a reordering.
    Stale {
        /// The number that was expected.
        expected: u64,
    },
}

/// Tracks a stream's sequence numbers.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SeqTracker {
    next: Option<u64>,
    /// Numbers received.
    pub received: u64,
    /// Numbers skipped in total.
    pub lost: u64,
    /// Numbers received out of order or twice.
    pub stale: u64,
}

impl SeqTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> SeqTracker {
        SeqTracker::default()
    }

    /// Records `seq` and classifies it.
    pub fn observe(&mut self, seq: u64) -> SeqEvent {
        self.received += 1;
        let event = match self.next {
            None => SeqEvent::First,
            Some(n) if seq == n => SeqEvent::InOrder,
            Some(n) if seq > n => {
                self.lost += seq - n;
                SeqEvent::Gap { missing: seq - n }
            }
            Some(n) => {
                self.stale += 1;
                return SeqEvent::Stale { expected: n };
            }
        };
        self.next = Some(seq + 1);
        event
    }

    /// The next expected number, if any was seen.
    pub fn expected(&self) -> Option<u64> {
        self.next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(4), SeqEvent::First);
        assert_eq!(t.observe(5), SeqEvent::InOrder);
        assert_eq!(t.observe(8), SeqEvent::Gap { missing: 2 });
        assert_eq!(t.observe(6), SeqEvent::Stale { expected: 9 });
        assert_eq!(t.observe(9), SeqEvent::InOrder);
        assert_eq!((t.received, t.lost, t.stale), (5, 2, 1));
    }
}
