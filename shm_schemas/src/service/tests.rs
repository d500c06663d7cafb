//! Tests of the service layer over real `ipc::Service` shared memory, each
//! with its own iceoryx2 prefix so they run in parallel; a few spawn this
//! test binary again as a second process ([`child_process_entry`]).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;

use std::path::Path as StdPath;

use iceoryx2::config::Config;

use super::files::{files_with_prefix, is_iceoryx2_name_after_prefix};
use super::*;
use crate::{
    Channel, EnvMeta, GraphEdge, MAX_ROUTE_LEN, ObsShape, RouteStatus, SCHEMA_VERSION, SchemaError,
    SeqEvent, SeqTracker, ShmError,
};

/// Environment variable selecting a child role in [`child_process_entry`].
const CHILD_ROLE: &str = "WG_SHM_TEST_CHILD";
const CHILD_PREFIX: &str = "WG_SHM_TEST_PREFIX";
const CHILD_RUN: &str = "WG_SHM_TEST_RUN";
/// Upper bound for anything that waits on another port or process.
const WATCHDOG: Duration = Duration::from_secs(10);
/// The process-wide backstop behind [`WATCHDOG`] (which fails a test with
/// a message): ends the process if a test hangs in a blocking call.
const HARD_WATCHDOG: Duration = Duration::from_secs(60);

/// Ends the whole process if a test hangs (a deadlock is reported as a
/// failure, never waited out); disarmed on drop.
struct Watchdog {
    disarm: Option<mpsc::Sender<()>>,
}

impl Watchdog {
    fn arm(what: &'static str) -> Watchdog {
        let (tx, rx) = mpsc::channel::<()>();
        std::thread::spawn(move || {
            if let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(HARD_WATCHDOG) {
                eprintln!("watchdog: `{what}` still running after {HARD_WATCHDOG:?}, aborting");
                std::process::exit(101);
            }
        });
        Watchdog { disarm: Some(tx) }
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        if let Some(tx) = self.disarm.take() {
            let _ = tx.send(());
        }
    }
}

/// A unique prefix per test and process; removes the prefix's leftover
/// `global_mgmt` segment when dropped (declare it first so it drops last).
struct TestPrefix {
    prefix: String,
    config: Config,
}

impl TestPrefix {
    fn new(test: &str) -> TestPrefix {
        let prefix = format!("wgtest_{test}_{}_", std::process::id());
        let config = isolated_config(&prefix).unwrap();
        TestPrefix { prefix, config }
    }
}

impl Drop for TestPrefix {
    fn drop(&mut self) {
        let _ = teardown_run::<ipc::Service>(&self.config);
    }
}

fn run() -> RunName {
    RunName::new("test-run").unwrap()
}

fn node(t: &TestPrefix, name: &str) -> PipelineNode<ipc::Service> {
    PipelineNode::new(&t.config, run(), name)
        .unwrap()
        .with_retry_timeout(Duration::from_secs(2))
}

/// Polls `f` until it yields a value or the deadline passes.
fn poll<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + WATCHDOG;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_micros(200));
    }
}

/// Like [`poll`] but spinning (yielding the CPU), for latency figures.
fn poll_spin<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + WATCHDOG;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::yield_now();
    }
}

/// Cell contents the writer of batch `seq` puts at `(env, i)`.
fn cell_value(seq: u64, env: usize, i: usize) -> u8 {
    (seq as usize * 31 + env * 7 + i) as u8
}

fn write_batch(sample: &mut ObsSampleMut<ipc::Service>, seq: u64) {
    let batch = sample.batch_mut();
    let cpe = batch.header.shape().cells_per_env();
    for (env, m) in batch.meta.iter_mut().enumerate() {
        *m = EnvMeta {
            reward: seq as f32,
            x: env as u16,
            y: 1,
            episode_len: seq as u32,
            ..EnvMeta::EMPTY
        };
    }
    for (i, c) in batch.cells.iter_mut().enumerate() {
        *c = cell_value(seq, i / cpe, i % cpe);
    }
}

fn check_batch(sample: &ObsSample<ipc::Service>, seq: u64) {
    let b = sample.batch();
    assert_eq!(b.header.seq, seq);
    assert_eq!(b.header.schema_version, SCHEMA_VERSION);
    assert!(b.header.send_time_ns > 0);
    let cpe = b.shape().cells_per_env();
    for (env, m) in b.meta.iter().enumerate() {
        assert_eq!(
            (m.reward, m.x, m.y, m.episode_len),
            (seq as f32, env as u16, 1, seq as u32)
        );
    }
    for env in 0..b.shape().envs() {
        let cells = b.env_cells(env);
        assert!(
            cells
                .iter()
                .enumerate()
                .all(|(i, &c)| c == cell_value(seq, env, i)),
            "env {env} of batch {seq}"
        );
        assert_eq!(cells.len(), cpe);
    }
}

#[test]
fn shm_file_names_of_one_run_only() {
    let hash = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5";
    assert!(is_iceoryx2_name_after_prefix(
        format!("{hash}_node.0_10_0.global_mgmt").as_bytes()
    ));
    assert!(is_iceoryx2_name_after_prefix(
        format!("{hash}_1584566279.data").as_bytes()
    ));
    // What follows `wg_a_` in a file of run `a_b`.
    assert!(!is_iceoryx2_name_after_prefix(
        format!("b_{hash}_node.0_10_0.global_mgmt").as_bytes()
    ));
    assert!(!is_iceoryx2_name_after_prefix(b"short"));
}

#[test]
fn obs_roundtrip_to_two_subscribers() {
    let _w = Watchdog::arm("obs_roundtrip_to_two_subscribers");
    let t = TestPrefix::new("obs");
    let shape = ObsShape::new(16, 13, 13).unwrap();
    let (sim, learner, planner) = (node(&t, "sim"), node(&t, "learner"), node(&t, "planner"));
    let learner_sub = learner.obs_subscriber(shape).unwrap();
    let planner_sub = planner.obs_subscriber(shape).unwrap();
    let publisher = sim.obs_publisher(shape).unwrap();
    let mut seqs = SeqTracker::new();
    for seq in 0..5 {
        let mut sample = publisher.loan(seq, seq * 10).unwrap();
        write_batch(&mut sample, seq);
        assert_eq!(sample.send().unwrap(), 2);
        let got = poll("obs batch", || learner_sub.receive().unwrap());
        check_batch(&got, seq);
        assert_eq!(got.header().step, seq * 10);
        assert_eq!(
            seqs.observe(got.header().seq),
            if seq == 0 {
                SeqEvent::First
            } else {
                SeqEvent::InOrder
            }
        );
    }
    // The planner did not read meanwhile: safe overflow kept the newest
    // OBS_BUFFER (4) of the 5.
    let kept: Vec<u64> = std::iter::from_fn(|| planner_sub.receive().unwrap())
        .map(|s| s.header().seq)
        .collect();
    assert_eq!(kept, vec![1, 2, 3, 4]);
    assert!(planner_sub.receive().unwrap().is_none());
}

/// Debug builds fill every loan with [`crate::SENTINEL_BYTE`], so a writer
/// that forgets a cell shows it to the reader instead of last batch's stale
/// byte. Release builds skip the fill; `make test` runs this crate once
/// with debug assertions, so this is checked.
#[test]
#[cfg_attr(not(debug_assertions), ignore = "the sentinel fill is debug-only")]
fn a_debug_build_fills_each_loan_with_the_sentinel() {
    let _w = Watchdog::arm("a_debug_build_fills_each_loan_with_the_sentinel");
    let t = TestPrefix::new("sentinel");
    let shape = ObsShape::new(2, 3, 3).unwrap();
    let (sim, learner) = (node(&t, "sim"), node(&t, "learner"));
    let subscriber = learner.obs_subscriber(shape).unwrap();
    let publisher = sim.obs_publisher(shape).unwrap();
    for seq in 0..3 {
        let mut sample = publisher.loan(seq, 0).unwrap();
        let batch = sample.batch_mut();
        batch.meta.fill(EnvMeta::EMPTY);
        // The writer "forgets" every cell but the first.
        batch.cells[0] = 1;
        sample.send().unwrap();
        let got = poll("obs batch", || subscriber.receive().unwrap());
        let cells = got.batch().cells;
        assert_eq!(cells[0], 1);
        assert!(
            cells[1..].iter().all(|&c| c == crate::SENTINEL_BYTE),
            "batch {seq}: unwritten cells hold the sentinel: {cells:?}"
        );
    }
}

#[test]
fn act_roundtrip() {
    let _w = Watchdog::arm("act_roundtrip");
    let t = TestPrefix::new("act");
    let (sim, learner) = (node(&t, "sim"), node(&t, "learner"));
    let sub = sim.act_subscriber(8).unwrap();
    let publisher = learner.act_publisher(8).unwrap();
    let mut sample = publisher.loan(41).unwrap();
    sample
        .batch_mut()
        .actions
        .copy_from_slice(&[0, 1, 2, 3, 4, 5, 6, 2]);
    sample.send().unwrap();
    publisher.send_actions(42, &[2; 8]).unwrap();
    let a = poll("action batch", || sub.receive().unwrap());
    assert_eq!(
        (a.header().seq, a.actions()),
        (41, &[0, 1, 2, 3, 4, 5, 6, 2][..])
    );
    let b = sub.receive().unwrap().unwrap();
    assert_eq!((b.header().seq, b.actions()), (42, &[2; 8][..]));
    assert!(matches!(
        publisher.send_actions(43, &[2; 7]),
        Err(ShmError::Schema(SchemaError::PayloadTooShort { .. }))
    ));
}

#[test]
fn route_roundtrip() {
    let _w = Watchdog::arm("route_roundtrip");
    let t = TestPrefix::new("route");
    let (planner, learner) = (node(&t, "planner"), node(&t, "learner"));
    let server = planner.route_server().unwrap();
    let client = learner.route_client().unwrap();

    let pending = client.request(3, 14, 0, 2).unwrap();
    let call = poll("route request", || server.receive().unwrap());
    assert_eq!(
        (
            call.request().env,
            call.request().from_cell,
            call.request().to_pivot
        ),
        (3, 14, 2)
    );
    assert_eq!(
        call.respond(7, RouteStatus::Ok, &[0, 2], &[15, 16, 29], &[2, 2, 1])
            .unwrap(),
        RouteStatus::Ok
    );
    let reply = pending.wait(WATCHDOG).unwrap();
    assert_eq!(reply.status(), Some(RouteStatus::Ok));
    assert_eq!(
        (
            reply.graph_version,
            reply.pivots(),
            reply.cells(),
            reply.actions()
        ),
        (7, &[0, 2][..], &[15, 16, 29][..], &[2, 2, 1][..])
    );

    // A route over capacity is answered with TooLong, not truncated.
    let pending = client.request(0, 1, 0, 5).unwrap();
    let call = poll("route request", || server.receive().unwrap());
    let long = vec![2u8; MAX_ROUTE_LEN + 1];
    let cells = vec![1u32; MAX_ROUTE_LEN + 1];
    assert_eq!(
        call.respond(7, RouteStatus::Ok, &[5], &cells, &long)
            .unwrap(),
        RouteStatus::TooLong
    );
    let reply = pending.wait(WATCHDOG).unwrap();
    let data: u64 = shm_files(&t.prefix)
        .unwrap()
        .iter()
        .filter(|(p, _)| p.to_string_lossy().ends_with(".data"))
        .map(|(p, _)| std::fs::metadata(p).unwrap().len())
        .max()
        .unwrap();
    eprintln!("route: largest data segment (server responses) {data} B");
    assert!(data < 8 << 20, "{data}");
    assert_eq!(
        (reply.status(), reply.actions().len()),
        (Some(RouteStatus::TooLong), 0)
    );
}

#[test]
fn route_edge_cases() {
    let _w = Watchdog::arm("route_edge_cases");
    let t = TestPrefix::new("routex");
    let (planner, learner) = (node(&t, "planner"), node(&t, "learner"));
    let server = planner.route_server().unwrap();

    // A client that gave up before the answer: responding is harmless.
    let client = learner.route_client().unwrap();
    let pending = client.request(0, 1, 0, 1).unwrap();
    let call = poll("route request", || server.receive().unwrap());
    drop(pending);
    assert!(!call.is_connected());
    call.respond(1, RouteStatus::Unreachable, &[], &[], &[])
        .unwrap();

    // A request of another schema version is answered BadRequest and reported.
    let (_, service) = learner.route_service().unwrap();
    let raw_client = service.client_builder().create().unwrap();
    let mut bad = RouteRequest::new(77, run().id(), 0, 1, 0, 1);
    bad.schema_version = 9;
    let pending = raw_client.send_copy(bad).unwrap();
    let err = poll("bad request", || match server.receive() {
        Ok(None) => None,
        other => Some(other),
    })
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "route request/response schema v9 on the wire, this process speaks v{SCHEMA_VERSION}"
        )
    );
    let answer = poll("bad request answer", || pending.receive().unwrap());
    assert_eq!(
        (answer.status(), answer.request_id),
        (Some(RouteStatus::BadRequest), 77)
    );
}

#[test]
fn graph_snapshot_reaches_late_joiner() {
    let _w = Watchdog::arm("graph_snapshot_reaches_late_joiner");
    let t = TestPrefix::new("graph");
    let (planner, viewer) = (node(&t, "planner"), node(&t, "viewer"));
    let publisher = planner.graph_publisher(25, 19).unwrap();
    let edges = [
        GraphEdge {
            from: 0,
            to: 1,
            weight: 9,
        },
        GraphEdge {
            from: 1,
            to: 0,
            weight: 9,
        },
    ];
    publisher.publish(1, &[26, 40], &edges).unwrap();
    // A bigger second version than the initial slice: the segment regrows.
    let many_nodes: Vec<u32> = (0..300).collect();
    let many_edges: Vec<GraphEdge> = (0..10_000)
        .map(|i| GraphEdge {
            from: (i % 300) as u16,
            to: ((i + 1) % 300) as u16,
            weight: i,
        })
        .collect();
    publisher.publish(2, &many_nodes, &many_edges).unwrap();

    let sub = viewer.graph_subscriber(25, 19).unwrap();
    let s = poll("graph snapshot", || {
        publisher.update_connections().unwrap();
        sub.receive().unwrap()
    });
    let g = s.snapshot();
    assert_eq!(
        (g.header.graph_version, g.nodes.len(), g.edges.len()),
        (2, 300, 10_000)
    );
    assert_eq!(g.edges[9_999], many_edges[9_999]);
    assert!(g.header.send_time_ns > 0);
}

/// A stand-in for a future `ObsHeader` with another schema version.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("wg.ObsHeader.v99")]
struct ObsHeaderV99 {
    words: [u64; 6],
}

/// The `ObsHeader` of schema v2 (before the end pose and the final cells
/// of issue 24): same size, its own type name.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("wg.ObsHeader.v2")]
struct ObsHeaderV2 {
    words: [u64; 6],
}

/// Creates `wg/<run>/obs` for `shape` as a writer of schema `version`
/// would: its user header `H` and its `wg.schema_version` attribute.
fn create_obs_service_of_version<H: std::fmt::Debug + ZeroCopySend>(
    node: &PipelineNode<ipc::Service>,
    shape: ObsShape,
    version: u32,
) -> iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, [u64], H> {
    let name = service_name(node.run(), Channel::Obs).unwrap();
    let attr =
        |key: &str, value: String| (key.try_into().unwrap(), value.as_str().try_into().unwrap());
    let attrs = [
        attr(ATTR_SCHEMA_VERSION, version.to_string()),
        attr(ATTR_NUM_ENVS, shape.num_envs.to_string()),
        attr(ATTR_GRID, shape.grid_attr()),
        attr(ATTR_SLICES, shape.slices.to_string()),
    ]
    .iter()
    .fold(AttributeSpecifier::new(), |a, (k, v)| {
        a.define(k, v).unwrap()
    });
    node.node()
        .service_builder(&name)
        .publish_subscribe::<[u64]>()
        .user_header::<H>()
        .create_with_attributes(&attrs)
        .unwrap()
}

#[test]
fn other_schema_version_is_refused_at_open() {
    let _w = Watchdog::arm("other_schema_version_is_refused_at_open");
    let t = TestPrefix::new("schema");
    let shape = ObsShape::new(4, 13, 13).unwrap();
    let future = node(&t, "future_sim");
    let _v99 = create_obs_service_of_version::<ObsHeaderV99>(&future, shape, 99);

    let learner = node(&t, "learner");
    let err = learner.obs_subscriber(shape).unwrap_err();
    assert!(
        matches!(
            err,
            ShmError::Schema(SchemaError::SchemaVersion {
                channel: Channel::Obs,
                wire: 99,
                ours: SCHEMA_VERSION
            })
        ),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        format!("observation batch schema v99 on the wire, this process speaks v{SCHEMA_VERSION}")
    );
}

/// A simulator of schema v2, in another process, holds the run's
/// observation service: a v3 reader is refused, the message naming both
/// versions, and neither the reader nor the publisher side is created.
#[test]
fn a_v2_process_is_refused_by_a_v3_reader_naming_both_versions() {
    assert_eq!(SCHEMA_VERSION, 3, "update the stand-in and this test");
    let _w = Watchdog::arm("a_v2_process_is_refused_by_a_v3_reader_naming_both_versions");
    let t = TestPrefix::new("v2proc");
    let mut child = spawn_child_with(CHILD_V2_SIM, &t, |c| {
        c.stdin(Stdio::piped()).stdout(Stdio::piped());
    });
    // The child's stdout stays open until it exits (libtest still writes
    // there), so the rest is drained below.
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let ready = lines
        .by_ref()
        .map_while(Result::ok)
        .any(|l| l.ends_with(CHILD_READY));
    assert!(ready, "the v2 child never created its service");

    let shape = two_process_shape();
    let learner = node(&t, "learner");
    for err in [
        learner.obs_subscriber(shape).unwrap_err(),
        learner.obs_publisher(shape).unwrap_err(),
    ] {
        assert!(
            matches!(
                err,
                ShmError::Schema(SchemaError::SchemaVersion {
                    channel: Channel::Obs,
                    wire: 2,
                    ours: 3
                })
            ),
            "{err:?}"
        );
        assert_eq!(
            err.to_string(),
            "observation batch schema v2 on the wire, this process speaks v3"
        );
    }
    drop(child.stdin.take());
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    assert!(reap(child).success(), "{rest:?}");
}

#[test]
fn other_schema_version_in_a_header_is_refused() {
    let _w = Watchdog::arm("other_schema_version_in_a_header_is_refused");
    let t = TestPrefix::new("hdrver");
    let shape = ObsShape::new(2, 5, 5).unwrap();
    let (sim, learner) = (node(&t, "sim"), node(&t, "learner"));
    let sub = learner.obs_subscriber(shape).unwrap();
    let publisher = sim.obs_publisher(shape).unwrap();
    let mut sample = publisher.loan(0, 0).unwrap();
    sample.batch_mut().header.schema_version = 9;
    sample.send().unwrap();
    let err = poll("refused batch", || match sub.receive() {
        Ok(None) => None,
        other => Some(other),
    })
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("observation batch schema v9 on the wire, this process speaks v{SCHEMA_VERSION}")
    );
    // A header of the previous version (v2) is refused the same way.
    let mut sample = publisher.loan(1, 0).unwrap();
    sample.batch_mut().header.schema_version = SCHEMA_VERSION - 1;
    sample.send().unwrap();
    let err = poll("refused batch", || match sub.receive() {
        Ok(None) => None,
        other => Some(other),
    })
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "observation batch schema v{} on the wire, this process speaks v{SCHEMA_VERSION}",
            SCHEMA_VERSION - 1
        )
    );
}

#[test]
fn other_grid_or_batch_size_is_refused() {
    let _w = Watchdog::arm("other_grid_or_batch_size_is_refused");
    let t = TestPrefix::new("shape");
    let (sim, learner) = (node(&t, "sim"), node(&t, "learner"));
    let _publisher = sim
        .obs_publisher(ObsShape::new(64, 25, 19).unwrap())
        .unwrap();

    let err = learner
        .obs_subscriber(ObsShape::new(64, 13, 13).unwrap())
        .unwrap_err();
    assert!(
        matches!(
            err,
            ShmError::Schema(SchemaError::GridShape {
                expected: (13, 13),
                wire: (25, 19),
                ..
            })
        ),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        "observation batch: grid 13x13 expected, publisher sends 25x19"
    );

    let err = learner
        .obs_subscriber(ObsShape::new(32, 25, 19).unwrap())
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "observation batch: batch of 32 environments expected, publisher sends 64"
    );

    let _acts = sim.act_subscriber(64).unwrap();
    let err = learner.act_publisher(16).unwrap_err();
    assert!(
        matches!(
            err,
            ShmError::Schema(SchemaError::BatchSize {
                channel: Channel::Act,
                expected: 16,
                wire: 64
            })
        ),
        "{err:?}"
    );

    let _graph = sim.graph_publisher(25, 19).unwrap();
    let err = learner.graph_subscriber(13, 13).unwrap_err();
    assert_eq!(
        err.to_string(),
        "graph snapshot: grid 13x13 expected, publisher sends 25x19"
    );
}

#[test]
fn second_publisher_for_a_run_is_refused() {
    let _w = Watchdog::arm("second_publisher_for_a_run_is_refused");
    let t = TestPrefix::new("twopub");
    let shape = ObsShape::new(4, 5, 5).unwrap();
    let (a, b) = (node(&t, "sim_a"), node(&t, "sim_b"));
    let _first = a.obs_publisher(shape).unwrap();
    let b = b.with_retry_timeout(Duration::from_millis(50));
    let err = b.obs_publisher(shape).unwrap_err();
    assert!(
        matches!(
            err,
            ShmError::Timeout {
                op: "create publisher",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn shared_memory_is_private_and_torn_down() {
    let _w = Watchdog::arm("shared_memory_is_private_and_torn_down");
    let t = TestPrefix::new("perm");
    {
        let shape = ObsShape::new(4, 5, 5).unwrap();
        let (sim, learner, planner) = (node(&t, "sim"), node(&t, "learner"), node(&t, "planner"));
        let _o = (
            sim.obs_publisher(shape).unwrap(),
            learner.obs_subscriber(shape).unwrap(),
        );
        let _a = (
            learner.act_publisher(4).unwrap(),
            sim.act_subscriber(4).unwrap(),
        );
        let _r = (
            planner.route_server().unwrap(),
            learner.route_client().unwrap(),
        );
        let _g = (
            planner.graph_publisher(5, 5).unwrap(),
            learner.graph_subscriber(5, 5).unwrap(),
        );
        let files = shm_files(&t.prefix).unwrap();
        assert!(files.len() > 4, "{files:?}");
        for (path, mode) in &files {
            assert_eq!(mode & 0o077, 0, "{} has mode {mode:o}", path.display());
        }
        // iceoryx2's own files (service descriptions, node monitors, event
        // sockets) under the root path: none for other users either.
        let root = t.config.global.root_path().to_string();
        for dir in ["", "nodes", "services"] {
            for (path, mode) in
                files_with_prefix(&StdPath::new(&root).join(dir), &t.prefix).unwrap()
            {
                assert_eq!(mode & 0o007, 0, "{} has mode {mode:o}", path.display());
            }
        }
        assert!(matches!(
            teardown_run::<ipc::Service>(&t.config),
            Err(ShmError::StillInUse { alive: 3, .. })
        ));
    }
    let left = teardown_run::<ipc::Service>(&t.config).unwrap();
    assert!(left.is_empty(), "{left:?}");
    assert!(shm_files(&t.prefix).unwrap().is_empty());
}

// ------------------------------------------------------------ two processes

/// Spawns this test binary running only [`child_process_entry`] in `role`.
fn spawn_child(role: &str, t: &TestPrefix) -> Child {
    spawn_child_with(role, t, |_| {})
}

/// [`spawn_child`], with `setup` applied to the command (stdio).
fn spawn_child_with(role: &str, t: &TestPrefix, setup: impl FnOnce(&mut Command)) -> Child {
    let mut command = Command::new(std::env::current_exe().unwrap());
    command
        .args([
            "--exact",
            "service::tests::child_process_entry",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ROLE, role)
        .env(CHILD_PREFIX, &t.prefix)
        .env(CHILD_RUN, run().as_str());
    setup(&mut command);
    command.spawn().unwrap()
}

/// Child role: a simulator of schema v2 holding the observation service
/// until its stdin closes.
const CHILD_V2_SIM: &str = "v2_sim";
/// What a child prints once its service exists.
const CHILD_READY: &str = "child ready";

fn two_process_shape() -> ObsShape {
    ObsShape::new(
        TWO_PROCESS_SHAPE.0,
        TWO_PROCESS_SHAPE.1,
        TWO_PROCESS_SHAPE.2,
    )
    .unwrap()
}

/// Waits for `child` (reaping it: a zombie would look alive to iceoryx2),
/// killing it if it outlives the watchdog.
fn reap(mut child: Child) -> std::process::ExitStatus {
    let deadline = Instant::now() + WATCHDOG;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("child process did not finish within {WATCHDOG:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

const TWO_PROCESS_BATCHES: u64 = 50;
const TWO_PROCESS_SHAPE: (usize, usize, usize) = (256, 25, 19);

/// Child roles; does nothing in a normal test run.
#[test]
fn child_process_entry() {
    let Ok(role) = std::env::var(CHILD_ROLE) else {
        return;
    };
    let _w = Watchdog::arm("child process");
    let config = isolated_config(&std::env::var(CHILD_PREFIX).unwrap()).unwrap();
    let run = RunName::new(&std::env::var(CHILD_RUN).unwrap()).unwrap();
    let shape = ObsShape::new(
        TWO_PROCESS_SHAPE.0,
        TWO_PROCESS_SHAPE.1,
        TWO_PROCESS_SHAPE.2,
    )
    .unwrap();
    match role.as_str() {
        // A simulator in lock-step: publish batch k written in place, wait for action k.
        "sim" => {
            let sim = PipelineNode::<ipc::Service>::new(&config, run, "child_sim").unwrap();
            let publisher = sim.obs_publisher(shape).unwrap();
            let actions = sim.act_subscriber(shape.envs()).unwrap();
            for seq in 0..TWO_PROCESS_BATCHES {
                let mut sample = publisher.loan(seq, seq).unwrap();
                write_batch(&mut sample, seq);
                sample.send().unwrap();
                let act = poll_spin("action batch", || actions.receive().unwrap());
                assert_eq!(act.header().seq, seq);
                assert!(act.actions().iter().all(|&a| a == (seq % 3) as u8));
            }
        }
        // A simulator of schema v2: its service, no ports, until stdin closes.
        CHILD_V2_SIM => {
            let sim = PipelineNode::<ipc::Service>::new(&config, run, "v2_sim").unwrap();
            let _service = create_obs_service_of_version::<ObsHeaderV2>(&sim, shape, 2);
            println!("{CHILD_READY}");
            std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new()).unwrap();
        }
        // A process that dies holding a node and a publisher.
        "crash" => {
            let sim = PipelineNode::<ipc::Service>::new(&config, run, "doomed_sim").unwrap();
            let _publisher = sim.obs_publisher(shape).unwrap();
            std::process::abort();
        }
        other => panic!("unknown child role {other}"),
    }
}

#[test]
fn two_processes_lock_step_zero_copy() {
    let _w = Watchdog::arm("two_processes_lock_step_zero_copy");
    let t = TestPrefix::new("twoproc");
    let shape = ObsShape::new(
        TWO_PROCESS_SHAPE.0,
        TWO_PROCESS_SHAPE.1,
        TWO_PROCESS_SHAPE.2,
    )
    .unwrap();
    let learner = node(&t, "learner");
    let obs = learner.obs_subscriber(shape).unwrap();
    let actions = learner.act_publisher(shape.envs()).unwrap();
    let child = spawn_child("sim", &t);

    let mut seqs = SeqTracker::new();
    let mut latencies = Vec::new();
    for seq in 0..TWO_PROCESS_BATCHES {
        let sample = poll_spin("obs batch from the child", || obs.receive().unwrap());
        latencies.push(sample.latency_ns());
        check_batch(&sample, seq);
        assert_ne!(
            seqs.observe(sample.header().seq),
            SeqEvent::Stale { expected: seq }
        );
        drop(sample);
        actions
            .send_actions(seq, &vec![(seq % 3) as u8; shape.envs()])
            .unwrap();
    }
    assert!(reap(child).success());
    assert_eq!(
        (seqs.received, seqs.lost, seqs.stale),
        (TWO_PROCESS_BATCHES, 0, 0)
    );
    latencies.sort_unstable();
    eprintln!(
        "two processes: {} batches of {} B, one-way latency p50 {} ns, max {} ns",
        TWO_PROCESS_BATCHES,
        shape.payload_bytes(),
        latencies[latencies.len() / 2],
        latencies[latencies.len() - 1]
    );
}

#[test]
fn dead_publisher_is_detected_and_replaced() {
    let _w = Watchdog::arm("dead_publisher_is_detected_and_replaced");
    let t = TestPrefix::new("dead");
    let shape = ObsShape::new(
        TWO_PROCESS_SHAPE.0,
        TWO_PROCESS_SHAPE.1,
        TWO_PROCESS_SHAPE.2,
    )
    .unwrap();
    let status = reap(spawn_child("crash", &t));
    assert!(!status.success());

    let dead = list_dead_nodes::<ipc::Service>(&t.config).unwrap();
    assert_eq!(dead.len(), 1, "{dead:?}");
    assert_eq!(dead[0].name, "doomed_sim");
    let cleaned = cleanup_dead_nodes::<ipc::Service>(&t.config, Duration::from_secs(1)).unwrap();
    assert_eq!((cleaned.cleanups, cleaned.failed_cleanups), (1, 0));
    assert!(list_nodes::<ipc::Service>(&t.config).unwrap().is_empty());

    // The single publisher slot is free again.
    let sim = node(&t, "sim");
    let _publisher = sim.obs_publisher(shape).unwrap();
}

#[test]
fn force_removal_of_a_crashed_runs_services() {
    let _w = Watchdog::arm("force_removal_of_a_crashed_runs_services");
    let t = TestPrefix::new("force");
    let status = reap(spawn_child("crash", &t));
    assert!(!status.success());
    let sim = node(&t, "sim");
    // Node creation cleaned the dead node up already; whatever is left of
    // the run's services goes, and the run starts afresh.
    let removed = sim.force_remove_stale_services().unwrap();
    assert!(removed <= 1, "{removed}");
    let shape = ObsShape::new(
        TWO_PROCESS_SHAPE.0,
        TWO_PROCESS_SHAPE.1,
        TWO_PROCESS_SHAPE.2,
    )
    .unwrap();
    let _publisher = sim.obs_publisher(shape).unwrap();

    // Refused once the node has opened ports, and while other nodes live.
    assert!(matches!(
        sim.force_remove_stale_services(),
        Err(ShmError::Ipc { .. })
    ));
    let fresh = node(&t, "learner");
    assert!(matches!(
        fresh.force_remove_stale_services(),
        Err(ShmError::StillInUse { alive: 1, .. })
    ));
}

#[test]
fn obs_memory_scales_with_the_shape() {
    let _w = Watchdog::arm("obs_memory_scales_with_the_shape");
    // Chunks per obs publisher: subscribers × (buffer + borrowed) + history + loans.
    let chunks = OBS_MAX_SUBSCRIBERS * (OBS_BUFFER + OBS_MAX_BORROWED) + 1 + OBS_MAX_LOANS;
    let mut sizes = Vec::new();
    for (test, (n, w, h)) in [("mem_small", (64, 13, 13)), ("mem_large", (1024, 25, 19))] {
        let t = TestPrefix::new(test);
        let shape = ObsShape::new(n, w, h).unwrap();
        let sim = node(&t, "sim");
        let _publisher = sim.obs_publisher(shape).unwrap();
        let data: Vec<u64> = shm_files(&t.prefix)
            .unwrap()
            .iter()
            .filter(|(p, _)| p.to_string_lossy().ends_with(".data"))
            .map(|(p, _)| std::fs::metadata(p).unwrap().len())
            .collect();
        assert_eq!(data.len(), 1, "one data segment expected");
        let per_chunk = data[0] as usize / chunks;
        eprintln!(
            "obs {n} envs x {w}x{h}: payload {} B, data segment {} B = {chunks} chunks of ~{per_chunk} B",
            shape.payload_bytes(),
            data[0]
        );
        assert!(
            per_chunk >= shape.payload_bytes() && per_chunk < shape.payload_bytes() + 4096,
            "{per_chunk}"
        );
        sizes.push(data[0]);
    }
    assert!(sizes[0] * 10 < sizes[1]);
}

#[test]
fn threadsafe_service_ports_move_between_threads() {
    let _w = Watchdog::arm("threadsafe_service_ports_move_between_threads");
    let t = TestPrefix::new("threads");
    let shape = ObsShape::new(4, 5, 5).unwrap();
    let sim = PipelineNode::<ipc_threadsafe::Service>::new(&t.config, run(), "sim").unwrap();
    let learner =
        PipelineNode::<ipc_threadsafe::Service>::new(&t.config, run(), "learner").unwrap();
    let subscriber = learner.obs_subscriber(shape).unwrap();
    let publisher = sim.obs_publisher(shape).unwrap();
    let reader = std::thread::spawn(move || {
        let sample = poll("obs batch on another thread", || {
            subscriber.receive().unwrap()
        });
        sample.batch().cells.iter().map(|&c| c as u32).sum::<u32>()
    });
    let mut sample = publisher.loan(0, 0).unwrap();
    let batch = sample.batch_mut();
    batch.meta.fill(EnvMeta::EMPTY);
    batch.cells.fill(2);
    sample.send().unwrap();
    assert_eq!(reader.join().unwrap(), 2 * 4 * 25);
}
