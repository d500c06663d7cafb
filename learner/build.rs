//! Gives the `worldgraph` binary, tests and benches an rpath to libtorch, so
//! they run without `LD_LIBRARY_PATH` (see scripts/setup-libtorch.sh).
fn main() {
    println!("cargo:rerun-if-env-changed=LIBTORCH");
    if let Ok(dir) = std::env::var("LIBTORCH") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}/lib");
    }
}
