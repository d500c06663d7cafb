#!/usr/bin/env bash
# Fetches libtorch 2.13.0 (the version tch 0.26 expects) from PyPI alone and
# unpacks it where `.cargo/config.toml` points LIBTORCH: `.cache/libtorch`.
#
# The CPU libraries and headers come from the `torch==2.13.0` wheel;
# `libtorch_cpu.so` also links `libcudart.so.13` and `libcupti.so.13`, which
# come from the small `nvidia-cuda-runtime` / `nvidia-cuda-cupti` 13.0 wheels.
# Nothing is downloaded from anywhere but the package registry.
#
# Cached twice: the wheels and the unpacked tree live in
# ${WORLDGRAPH_CACHE:-$HOME/.cache/worldgraph}, shared by every checkout, and
# `.cache/libtorch` is a link to it. Running it again is a no-op (< 0.1 s).
set -euo pipefail

TORCH_VERSION=2.13.0
root=$(cd "$(dirname "$0")/.." && pwd)
cache=${WORLDGRAPH_CACHE:-$HOME/.cache/worldgraph}
dest="$cache/libtorch-$TORCH_VERSION"
link="$root/.cache/libtorch"
stamp="$dest/.complete"

if [ ! -f "$stamp" ]; then
  echo "setup-libtorch: fetching libtorch $TORCH_VERSION from PyPI into $dest" >&2
  wheels="$cache/wheels"
  mkdir -p "$wheels"
  pip_dl() { python3 -m pip download --quiet --no-deps --disable-pip-version-check -d "$wheels" "$@"; }
  ls "$wheels"/torch-$TORCH_VERSION-*.whl >/dev/null 2>&1 || pip_dl "torch==$TORCH_VERSION"
  ls "$wheels"/nvidia_cuda_runtime-13.0*.whl >/dev/null 2>&1 || pip_dl 'nvidia-cuda-runtime==13.0.*'
  ls "$wheels"/nvidia_cuda_cupti-13.0*.whl >/dev/null 2>&1 || pip_dl 'nvidia-cuda-cupti==13.0.*'

  # Unpack into a temporary sibling and rename at the end, so an interrupted
  # run never leaves a half-populated tree that looks complete.
  tmp=$(mktemp -d "$cache/.libtorch-tmp.XXXXXX")
  trap 'rm -rf "$tmp"' EXIT
  torch_whl=$(ls "$wheels"/torch-$TORCH_VERSION-*.whl | head -n1)
  python3 - "$torch_whl" "$tmp" <<'PY'
import sys, zipfile, os, shutil
whl, out = sys.argv[1], sys.argv[2]
libs = {"libtorch_cpu.so", "libtorch.so", "libc10.so", "libgomp.so.1"}
with zipfile.ZipFile(whl) as z:
    for name in z.namelist():
        if name.endswith("/"):
            continue
        if name.startswith("torch/include/"):
            target = os.path.join(out, "include", name[len("torch/include/"):])
        elif name.startswith("torch/lib/") and os.path.basename(name) in libs:
            target = os.path.join(out, "lib", os.path.basename(name))
        else:
            continue
        os.makedirs(os.path.dirname(target), exist_ok=True)
        with z.open(name) as src, open(target, "wb") as dst:
            shutil.copyfileobj(src, dst)
PY
  for whl in "$wheels"/nvidia_cuda_runtime-13.0*.whl "$wheels"/nvidia_cuda_cupti-13.0*.whl; do
    python3 - "$whl" "$tmp/lib" <<'PY'
import sys, zipfile, os, shutil
whl, out = sys.argv[1], sys.argv[2]
want = {"libcudart.so.13", "libcupti.so.13"}
with zipfile.ZipFile(whl) as z:
    for name in z.namelist():
        if os.path.basename(name) in want:
            with z.open(name) as src, open(os.path.join(out, os.path.basename(name)), "wb") as dst:
                shutil.copyfileobj(src, dst)
PY
  done
  for f in libtorch_cpu.so libtorch.so libc10.so libgomp.so.1 libcudart.so.13 libcupti.so.13; do
    [ -f "$tmp/lib/$f" ] || { echo "setup-libtorch: $f missing from the wheels" >&2; exit 1; }
  done
  [ -f "$tmp/include/torch/csrc/api/include/torch/torch.h" ] || { echo "setup-libtorch: headers missing" >&2; exit 1; }
  echo "$TORCH_VERSION" > "$tmp/build-version"
  touch "$tmp/.complete"
  rm -rf "$dest"
  mv "$tmp" "$dest"
  trap - EXIT
fi

mkdir -p "$root/.cache"
if [ "$(readlink "$link" 2>/dev/null)" != "$dest" ]; then
  rm -rf "$link"
  ln -s "$dest" "$link"
fi
echo "$link"
