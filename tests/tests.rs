//! Cross-crate and multi-process tests, built as one binary.

// The `worldgraph` command line: sim render/trace, bench sim, layout errors.
mod cli;
