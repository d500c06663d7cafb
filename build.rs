//! Gives the `worldgraph` binary, tests and benches an rpath to libtorch, so
//! they run without `LD_LIBRARY_PATH` (see scripts/setup-libtorch.sh), and
//! records the commit the binary is built from (`WORLDGRAPH_BUILD_COMMIT`:
//! `git rev-parse HEAD`, `+dirty` when tracked files had changes, `unknown`
//! outside a git checkout), which every run directory records.
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    Command::new("git")
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    if let Ok(dir) = std::env::var("LIBTORCH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}/lib");
    }
    let commit = match git(&["rev-parse", "HEAD"]) {
        Some(head) => match git(&["status", "--porcelain", "--untracked-files=no"]) {
            Some(s) if !s.is_empty() => format!("{head}+dirty"),
            _ => head,
        },
        None => "unknown".to_string(),
    };
    println!("cargo:rustc-env=WORLDGRAPH_BUILD_COMMIT={commit}");
    // A new commit, or an edit to any source the binary is built from,
    // records again (a directory is watched whole).
    // (`--git-path` resolves inside a worktree too; a ref that `git gc`
    // packed lives in `packed-refs`.)
    let mut watch = vec!["HEAD".to_string(), "packed-refs".to_string()];
    watch.extend(git(&["symbolic-ref", "-q", "HEAD"]));
    for name in watch {
        if let Some(p) = git(&["rev-parse", "--git-path", &name])
            && std::path::Path::new(&p).exists()
        {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    for src in [
        "src",
        "learner",
        "planner",
        "sim",
        "shm_schemas",
        "Cargo.toml",
        "Cargo.lock",
    ] {
        println!("cargo:rerun-if-changed={src}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
