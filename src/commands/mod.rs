//! One module per top-level command.

pub mod aggregate;
pub mod bench;
pub mod bench_learner;
pub mod bench_pipeline;
pub mod bench_planner;
pub mod clean;
pub mod demo;
pub mod discover;
pub mod evaluate;
pub mod experiment;
pub mod run;
pub mod sim;
pub mod soak;
pub mod soak_report;
pub mod soak_training;
pub mod table;
pub mod train;
