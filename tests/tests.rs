//! Cross-crate and multi-process tests, built as one binary.

// The `worldgraph` command line: sim render/trace, bench sim, layout errors.
mod cli;
// World-graph discovery: in-process equals pipeline; resume after a kill.
mod discover;
// The three processes over shared memory: exchange, refusal, death and rejoin.
mod pipeline;
// Stage 2: the protocol's files, determinism, kill and resume, refusals.
mod train;
// The paper's experiments: a grid's summaries, restart, reproduce, tables.
mod experiment;
// The grid on SLURM: job scripts, cells, --status; a real cluster when asked.
mod slurm;
// Property tests over layouts, discovery configs and role arguments.
mod fuzz;
// The docs stand alone: relative links resolve inside the repository.
mod docs;
// Failures that must be clean and runs that must not collide (issue 14).
mod reliability;
// The soak with a learner that trains π_g: kills cost at most a checkpoint.
mod soak;
