//! Property tests over what a user types: layouts, discovery configs and
//! the command-line arguments of the pipeline's roles. Whatever the input,
//! nothing panics or aborts, and every refusal is a message with a
//! non-zero exit. Case counts are fixed so the suite's time is bounded
//! (docs/implementation_details.md, "Reliability", gives them).

use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};

use proptest::prelude::*;

/// Property cases of the in-process properties.
const CASES: u32 = 256;
/// Property cases of the ones that start the binary (each a process).
const PROCESS_CASES: u32 = 40;

static RUNS: AtomicU64 = AtomicU64::new(0);

fn worldgraph(args: &[String]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_worldgraph"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("run worldgraph");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn assert_clean(code: Option<i32>, err: &str, what: &str) {
    assert!(
        code.is_some(),
        "{what}: killed by a signal (an abort): {err}"
    );
    for bad in ["panicked", "terminate called", "frame #"] {
        assert!(!err.contains(bad), "{what}: {bad:?} in: {err}");
    }
    if code != Some(0) {
        assert!(
            err.lines().any(|l| !l.trim().is_empty()),
            "{what}: a refusal without a message"
        );
    }
}

/// Layout text: mostly the layout alphabet, with ragged rows, odd
/// characters and sizes around the limits.
fn layout_text() -> impl Strategy<Value = String> {
    let cell = prop_oneof![
        8 => Just('#'),
        8 => Just('.'),
        1 => Just('E'),
        1 => Just('K'),
        1 => Just('D'),
        1 => Just('C'),
        1 => Just('O'),
        1 => Just('B'),
        1 => Just('L'),
        1 => Just('>'),
        1 => Just('v'),
        1 => Just('<'),
        1 => Just('^'),
        1 => Just('x'),
        1 => Just(' '),
        1 => Just('é'),
    ];
    prop::collection::vec(prop::collection::vec(cell, 0..20), 0..14).prop_map(|rows| {
        rows.into_iter()
            .map(|r| r.into_iter().collect::<String>())
            .collect::<Vec<_>>()
            .join("\n")
    })
}

/// Discovery config text: known and unknown keys, good and bad values.
fn config_text() -> impl Strategy<Value = String> {
    let key = prop_oneof![
        Just("seed"),
        Just("max_rounds"),
        Just("patience"),
        Just("walk_len"),
        Just("walk_steps_per_round"),
        Just("latent_batch"),
        Just("pivotal_ratio"),
        Just("from_pivotal"),
        Just("min_improvement"),
        Just("gcp_iters_per_round"),
        Just("buffer"),
        Just("unknown_key"),
    ];
    let value = prop_oneof![
        (0i64..100).prop_map(|v| v.to_string()),
        Just("-1".to_string()),
        Just("0.5".to_string()),
        Just("1e309".to_string()),
        Just("\"text\"".to_string()),
        Just("[1, 2]".to_string()),
        Just("nan".to_string()),
    ];
    prop::collection::vec((key, value), 0..6).prop_map(|kv| {
        kv.into_iter()
            .map(|(k, v)| format!("{k} = {v}\n"))
            .collect::<String>()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, ..ProptestConfig::default() })]

    #[test]
    fn parsing_any_layout_text_never_panics(text in layout_text()) {
        RUNS.fetch_add(1, Ordering::Relaxed);
        if let Ok(layout) = sim::Layout::parse("fuzz", &text) {
            // A layout that parses renders back to text that parses the same.
            let again = sim::Layout::parse("again", &layout.to_text()).unwrap();
            prop_assert_eq!(again.width, layout.width);
        }
    }

    #[test]
    fn any_discovery_config_text_is_read_or_refused_without_panicking(text in config_text()) {
        RUNS.fetch_add(1, Ordering::Relaxed);
        if let Ok(cfg) = toml::from_str::<learner::discovery::DiscoveryConfig>(&text) {
            let _ = cfg.validate();
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: PROCESS_CASES, ..ProptestConfig::default() })]

    #[test]
    fn the_binary_renders_or_refuses_any_layout_file(text in layout_text()) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fuzz.txt");
        std::fs::write(&path, &text).unwrap();
        let (code, err) = worldgraph(&[
            "sim".into(), "render".into(), "--layout".into(), path.display().to_string(),
        ]);
        assert_clean(code, &err, &format!("layout {text:?}"));
        prop_assert!(code == Some(0) || err.contains("fuzz.txt"), "{}", err);
    }

    #[test]
    fn discover_reads_or_refuses_any_config_file(text in config_text()) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.toml");
        std::fs::write(&path, &text).unwrap();
        // --rounds 0 is itself refused, so a config that reads is refused by
        // validation, never run: the property is about reading.
        let (code, err) = worldgraph(&[
            "discover".into(), "--run".into(), dir.path().join("r").display().to_string(),
            "--maze".into(), "small".into(), "--config".into(), path.display().to_string(),
            "--rounds".into(), "0".into(),
        ]);
        assert_clean(code, &err, &format!("config {text:?}"));
        prop_assert_ne!(code, Some(0));
    }

    #[test]
    fn a_role_runs_or_refuses_any_batch_arguments(
        envs in prop_oneof![Just(0usize), 1usize..300, Just(100_000)],
        slices in 0usize..6,
        maze in prop_oneof![Just("small"), Just("medium"), Just("large")],
        max_steps in prop_oneof![Just(None), Just(Some(0u32)), (1u32..5000).prop_map(Some)],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let n = RUNS.fetch_add(1, Ordering::Relaxed);
        let run = format!("fz{}-{n}", std::process::id());
        let mut args: Vec<String> = [
            "sim", "serve", "--run", &run, "--run-dir", dir.path().to_str().unwrap(),
            "--maze", maze, "--envs", &envs.to_string(), "--slices", &slices.to_string(),
            "--duration", "0.2",
        ].iter().map(|s| s.to_string()).collect();
        if let Some(m) = max_steps {
            args.extend(["--max-steps".into(), m.to_string()]);
        }
        let (code, err) = worldgraph(&args);
        assert_clean(code, &err, &format!("{args:?}"));
        prop_assert!(matches!(code, Some(0) | Some(2)), "status {:?}: {}", code, err);
    }
}
