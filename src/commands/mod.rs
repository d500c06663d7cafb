//! One module per top-level command.

pub mod bench;
pub mod demo;
pub mod run;
pub mod sim;
