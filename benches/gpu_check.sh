#!/usr/bin/env bash
# The renderer's checks for a machine with a real GPU, prepared here and run there in
# one go: a lent machine has no Rust toolchain, no network and only minutes.
#
#   bash benches/gpu_check.sh build    # here: release builds, stripped and compressed
#                                      # into target/gpu-check/, and the Vulkan loader
#                                      # packages into .gl/ (both ignored by git)
#   bash benches/gpu_check.sh run      # there, from the repository root, with
#                                      # target/gpu-check and .gl carried over
#
# `run` executes the GPU test suites (render/tests/gpu.rs and density.rs,
# viewer/tests/worker.rs) on the machine's driver, then the renderer benchmark at 2×10^6
# and 2×10^8 particles (crater data generated and converted there: about two minutes on
# 16 cores) into the BENCHMARKS.md sections `render-gpu`, `render-gpu-e4` and
# `render-gpu-errors` of a copy of BENCHMARKS.md. Logs, the test results and that copy
# go to $OUT (or target/gpu-check/out); copy the sections back from there. The `render-gpu`
# section also draws every particle up to FULL_MAX (default 2×10^8: about a minute
# there, 15 GB of host memory). SIZES, FULL_MAX, SKIP_TESTS=1 and SKIP_BENCH=1 narrow a
# run; a dry run on this machine's software driver:
#   SIZES=200000,2000000 bash benches/gpu_check.sh run
set -euo pipefail
cd "$(dirname "$0")/.."
DIR=target/gpu-check
mode=${1:-}

# The path of the executable cargo builds for one target (its JSON messages).
executable() {
  python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["target"]["name"] == sys.argv[1]:
        print(m["executable"])' "$1"
}

case "$mode" in
build)
  rm -rf "$DIR" && mkdir -p "$DIR"
  take() { # name path
    strip -o "$DIR/$1" "$2"
    xz -T0 -6 -f "$DIR/$1"
  }
  [ -n "$(git status --porcelain --untracked-files=no)" ] &&
    echo "note: uncommitted changes are built in" >&2
  bench=$(cargo bench --bench render --no-run --message-format=json 2>/dev/null | executable render)
  take render-bench "$bench"
  for t in gpu density; do
    take "test-$t" "$(cargo test --release -p mdlod-render --test $t --no-run \
      --message-format=json 2>/dev/null | executable $t)"
  done
  take test-worker "$(cargo test --release -p mdlod-viewer --test worker --no-run \
    --message-format=json 2>/dev/null | executable worker)"
  git rev-parse HEAD > "$DIR/commit"
  # The machine may lack the Vulkan loader: its packages travel and are unpacked there.
  if [ ! -d .gl ] && command -v apt-get > /dev/null; then
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update > /dev/null && (cd .gl && apt-get $o download libvulkan1 > /dev/null) ||
      echo "could not fetch the Vulkan loader package" >&2
  fi
  du -sh "$DIR" .gl 2>/dev/null || true
  ;;
run)
  OUT=${OUT:-$DIR/out}
  mkdir -p "$OUT" "$DIR/bin"
  for f in "$DIR"/*.xz; do
    b="$DIR/bin/$(basename "$f" .xz)"
    python3 -c 'import lzma, shutil, sys; shutil.copyfileobj(lzma.open(sys.argv[1]), open(sys.argv[2], "wb"))' "$f" "$b"
    chmod +x "$b"
  done
  if ! ldconfig -p 2> /dev/null | grep -q libvulkan && ls .gl/*.deb > /dev/null 2>&1; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
  fi
  if [ -e /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
    export VK_DRIVER_FILES=${VK_DRIVER_FILES:-/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json}
  fi
  echo "built from $(cat "$DIR/commit" 2>/dev/null || echo '?'), run at $(git rev-parse HEAD 2>/dev/null || echo '?')" | tee "$OUT/summary.txt"
  (nvidia-smi -L 2>/dev/null || echo "no nvidia-smi") | tee -a "$OUT/summary.txt"
  # The test binaries find their golden images through the path they were built at.
  built_at=$(grep -a -m1 -o '/[[:alnum:]/._-]*/render/tests/golden' "$DIR/bin/test-gpu" || true)
  if [ -n "$built_at" ] && [ ! -e "$built_at" ]; then
    mkdir -p "$(dirname "$built_at")" && ln -s "$PWD/render/tests/golden" "$built_at" ||
      echo "cannot link $built_at: golden-image tests will fail" | tee -a "$OUT/summary.txt"
  fi
  export WGPU_BACKEND=${WGPU_BACKEND:-vulkan}
  mkdir -p target/xdg && chmod 700 target/xdg
  export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$PWD/target/xdg}
  if [ "${SKIP_TESTS:-0}" != 1 ]; then
    for t in gpu density worker; do
      # Failures are recorded, not fatal: the benchmark still runs.
      if "$DIR/bin/test-$t" --test-threads=1 > "$OUT/test-$t.log" 2>&1; then r=ok; else r=FAILED; fi
      echo "test-$t: $r, $(grep -m1 '^test result' "$OUT/test-$t.log" || echo 'no result')" |
        tee -a "$OUT/summary.txt"
    done
  fi
  if [ "${SKIP_BENCH:-0}" != 1 ]; then
    # The sections are rewritten in a copy, which comes back in $OUT.
    cp BENCHMARKS.md "$OUT/BENCHMARKS.md"
    export MDLOD_BENCH_OUT="$OUT/BENCHMARKS.md"
    export MDLOD_RENDER_SIZES=${SIZES:-2000000,200000000} MDLOD_RENDER_FULL_MAX=0
    bench() { # log name, then environment assignments
      local log=$1
      shift
      if env "$@" "$DIR/bin/render-bench" > "$OUT/$log.log" 2>&1; then r=ok; else r=FAILED; fi
      echo "bench $log: $r" | tee -a "$OUT/summary.txt"
    }
    # The main section also draws every particle of the largest size (in batches).
    bench render MDLOD_BENCH_SECTION=render-gpu MDLOD_RENDER_FULL_MAX="${FULL_MAX:-200000000}"
    bench render-e4 MDLOD_BENCH_SECTION=render-gpu-e4 MDLOD_RENDER_ERROR=4 \
      MDLOD_RENDER_BUDGET=1000000000
    bench errors MDLOD_BENCH_SECTION=render-gpu MDLOD_RENDER_ONLY=errors
  fi
  ;;
*)
  echo "usage: bash benches/gpu_check.sh build|run" >&2
  exit 2
  ;;
esac
