//! Cross-crate and multi-process tests, one binary.
