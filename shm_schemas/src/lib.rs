//! # shm_schemas — the wire layout between worldgraph processes
//!
//! The only crate that knows how the sim, learner and planner processes lay
//! out the data they share over iceoryx2 (DESIGN.md section 2). Every type
//! here is `#[repr(C)]`, plain data, and carries a versioned type name.
//!
//! - [`EnvMeta`]: the per-environment record of a step (reward, flags, agent
//!   state, episode statistics). The simulator writes it directly into the
//!   observation batch in shared memory.
#![deny(unsafe_code)]

mod step;

pub use step::{EnvMeta, flags};
