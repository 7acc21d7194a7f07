#!/usr/bin/env bash
# The whole test suite: formatting, lints, and every test of every crate.
set -euo pipefail
cd "$(dirname "$0")/.."
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
mkdir -p target/xdg && chmod 700 target/xdg
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$PWD/target/xdg}"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --locked -- -D warnings
# cargo's rustc target probe has failed here in fresh clones after clippy (rustc read
# a build-script probe's error text as its input), and cargo caches the failure: build
# the tests, and on failure forget the cached probe and build them once more.
cargo test --workspace --locked --no-run ||
  { rm -f target/.rustc_info.json; cargo test --workspace --locked --no-run; }
cargo test --workspace --locked
