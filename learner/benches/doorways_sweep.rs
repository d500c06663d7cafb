//! The doorway experiment of `tests/pivotal_doorways.rs` over five seeds and
//! four kinds of data, printed (ranks, coverage against chance, the maps):
//! `cargo bench -p learner --bench doorways_sweep`, a few minutes. It
//! asserts nothing; the tests assert on seed 1.

#[allow(
    dead_code,
    reason = "the test file's helpers that only its #[test]s use are compiled here too"
)]
#[path = "../tests/pivotal_doorways.rs"]
mod pivotal_doorways;

fn main() -> anyhow::Result<()> {
    pivotal_doorways::sweep()
}
