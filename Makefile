# The two commands of the README. Both fetch what they need (libtorch from
# PyPI, crates from crates.io) on first use and cache it.
CARGO ?= cargo

.PHONY: demo test libtorch bench clean-shm

# The main job on the embedded default.
demo: libtorch
	$(CARGO) run --release --bin worldgraph -- demo

# Every test of the workspace (unit, property, multi-process, tch training);
# then the IPC and simulator crates once more with debug assertions on (the
# loan sentinel, debug_assert!s; profile debug-asserts in Cargo.toml), and
# the benches and examples, which must keep compiling; and the algorithm
# crates must not pull in the iceoryx2 transport (shm_schemas' `ipc` feature
# is the binary's alone).
test: libtorch
	$(CARGO) test --release --workspace --no-fail-fast
	$(CARGO) test --profile debug-asserts -p shm_schemas -p sim --no-fail-fast
	$(CARGO) build --release --workspace --benches --examples
	@for crate in sim planner learner; do \
	  if $(CARGO) tree -p $$crate -e normal --prefix none | grep -q '^iceoryx2 '; then \
	    echo "$$crate depends on iceoryx2: shm_schemas' ipc feature leaked into it" >&2; exit 1; fi; \
	done

libtorch:
	@./scripts/setup-libtorch.sh >/dev/null

bench: libtorch
	$(CARGO) run --release --bin worldgraph -- bench sim --maze medium --envs 1024 --threads 2 --seconds 5

# Remove shared-memory leftovers of killed test runs (iceoryx2 keeps one
# 16-byte global-management file per prefix).
clean-shm:
	rm -f /dev/shm/wgtest_* /dev/shm/iox2test_*
