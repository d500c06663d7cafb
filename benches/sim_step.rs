//! Simulator step throughput against batch size (criterion).
//! `cargo bench --bench sim_step`; the CLI's `bench sim` adds the memcpy bound.
#![allow(
    missing_docs,
    reason = "criterion_group! defines an undocumented pub fn"
)]

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use sim::{BatchEnv, EnvConfig, Maze, Task};

fn step_throughput(c: &mut Criterion) {
    let mut group = c.benchmark_group("sim_step/medium_multigoal");
    for &n in &[1usize, 64, 256, 1024] {
        let layout = Maze::Medium.layout(false);
        let cfg = EnvConfig::for_task(Task::MultiGoal, &layout);
        let mut batch = BatchEnv::new(layout, cfg, n, 0, if n >= 64 { 2 } else { 1 }).unwrap();
        let mut buf = batch.buffers();
        batch.reset(buf.out());
        let actions: Vec<u8> = (0..n + 3).map(|i| (i * 7 % 3) as u8).collect();
        let mut k = 0;
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, &n| {
            b.iter(|| {
                k = (k + 1) % 3;
                batch.step(&actions[k..k + n], buf.out());
            })
        });
    }
    group.finish();
}

criterion_group!(benches, step_throughput);
criterion_main!(benches);
