# The two commands of the README. Both fetch what they need (libtorch from
# PyPI, crates from crates.io) on first use and cache it.
CARGO ?= cargo

.PHONY: demo test test-slurm libtorch bench clean-shm python python-test bench-python torch-python bench-learner-python

# The Python package (python/): a project-owned virtual environment with
# pinned packages from PyPI, the extension built into it by maturin.
PYTHON ?= python3
VENV ?= .venv
VENV_ABS = $(abspath $(VENV))

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
	$(MAKE) --no-print-directory python-test WORLDGRAPH_REQUIRE_RUST=1

# `experiment --slurm` on a real SLURM: a one-node cluster on this machine
# (Debian's slurm-wlm and munge, installed if missing; needs root), a tiny
# grid submitted as job arrays and checked against the local runner, a
# cancelled cell resumed, slurmctld stopped and started mid-grid; the cluster
# is shut down afterwards (scripts/test-slurm.sh).
test-slurm: libtorch
	CARGO="$(CARGO)" bash scripts/test-slurm.sh

# The venv is (re)made when the pins change; nothing is installed by hand.
$(VENV)/.requirements: python/requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --disable-pip-version-check -q -r python/requirements.txt
	cp python/requirements.txt $@

# Builds the extension (release) and installs it into the venv, editable:
# python/worldgraph/ is imported from the source tree.
python: $(VENV)/.requirements
	cd python && VIRTUAL_ENV=$(VENV_ABS) PATH="$(VENV_ABS)/bin:$$PATH" maturin develop --release -q

# The package's pytest suite. The differential test runs the Rust reference
# example (built here), one test loads a run of the `worldgraph` binary's
# `discover` (built by `make test`'s cargo steps): under `make test`
# (WORLDGRAPH_REQUIRE_RUST=1) a missing binary fails, alone it is skipped.
python-test: python
	$(CARGO) build --release -p sim --example reference_rollout
	WORLDGRAPH_REFERENCE=$(abspath target/release/examples/reference_rollout) \
	WORLDGRAPH_BIN=$(abspath target/release/worldgraph) \
	WORLDGRAPH_REQUIRE_RUST=$(WORLDGRAPH_REQUIRE_RUST) \
	  $(VENV)/bin/python -m pytest python/tests -q

# env-steps/s from Python: this vector env against Gymnasium's SyncVectorEnv
# over MiniGrid's own env (installed here from python/requirements-bench.txt).
bench-python: python
	$(VENV)/bin/pip install --disable-pip-version-check -q -r python/requirements-bench.txt
	$(VENV)/bin/python python/bench/bench_envs.py

# PyTorch for the reference of `worldgraph bench learner`
# (benches/learner_pytorch.py), pinned in python/requirements-torch.txt to
# the libtorch the Rust learners link; from PyPI (pip may reuse the wheel
# scripts/setup-libtorch.sh cached). Not needed by `make test`.
WORLDGRAPH_CACHE ?= $(HOME)/.cache/worldgraph
$(VENV)/.requirements-torch: python/requirements-torch.txt $(VENV)/.requirements
	$(VENV)/bin/pip install --disable-pip-version-check -q \
	  --find-links $(WORLDGRAPH_CACHE)/wheels -r python/requirements-torch.txt
	$(VENV)/bin/python -c "import torch; torch.ones(2).sum()"
	cp python/requirements-torch.txt $@

torch-python: python $(VENV)/.requirements-torch

# The learner's env-steps/s against the PyTorch reference of the same
# networks and update, measured in the same run (the bench finds
# .venv/bin/python). Another agent or maze:
# `worldgraph bench learner --agent wn --maze medium --threads 1`.
bench-learner-python: libtorch torch-python
	$(CARGO) run --release --bin worldgraph -- bench learner --agent a2c --maze small --threads 1 --seconds 12

libtorch:
	@./scripts/setup-libtorch.sh >/dev/null

bench: libtorch
	$(CARGO) run --release --bin worldgraph -- bench sim --maze medium --envs 1024 --threads 2 --seconds 5

# Remove shared-memory leftovers of killed test runs (iceoryx2 keeps one
# 16-byte global-management file per prefix).
clean-shm:
	rm -f /dev/shm/wgtest_* /dev/shm/iox2test_*
