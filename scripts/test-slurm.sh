#!/usr/bin/env bash
# `make test-slurm`: `worldgraph experiment --slurm` on a real SLURM.
# Installs Debian's slurm-wlm and munge if missing (apt-get; needs root),
# starts a one-node cluster on this machine in a scratch folder
# (scripts/slurm-one-node.sh), runs the SLURM tests of tests/slurm.rs
# against it (the `#[ignore]`d ones: a grid as job arrays against the local
# runner, a cancelled cell resumed, slurmctld stopped and started mid-grid),
# and shuts the cluster down however they end. The folder (slurm.conf,
# daemon logs, job completion log) is kept when a test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
CARGO=${CARGO:-cargo}

bash scripts/slurm-one-node.sh install
cluster=$(mktemp -d /tmp/worldgraph-slurm.XXXXXX)
passed=0
finish() {
  bash scripts/slurm-one-node.sh stop "$cluster" || true
  for f in slurmctld.pid slurmd.pid; do
    if [ -s "$cluster/$f" ]; then
      echo "test-slurm: ${f%.pid} is still running (pid $(cat "$cluster/$f"))" >&2
      passed=0
    fi
  done
  if [ "$passed" = 1 ]; then
    rm -rf "$cluster"
  else
    echo "test-slurm: the cluster's folder is kept: $cluster" >&2
  fi
}
trap finish EXIT
bash scripts/slurm-one-node.sh start "$cluster"
export SLURM_CONF=$cluster/slurm.conf WORLDGRAPH_SLURM_CLUSTER=$cluster
start=$(date +%s)
nice -n 19 $CARGO test --release --test tests slurm:: -- --ignored --nocapture --test-threads=1
passed=1
echo "test-slurm: the SLURM tests took $(($(date +%s) - start)) s" >&2
