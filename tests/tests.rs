//! Cross-crate and multi-process tests, built as one binary.

// The `worldgraph` command line: sim render/trace, bench sim, layout errors.
mod cli;
// The three processes over shared memory: exchange, refusal, death and rejoin.
mod pipeline;
