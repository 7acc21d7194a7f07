#!/usr/bin/env bash
# The whole test suite: formatting, lints, and every test of every crate.
set -euo pipefail
cd "$(dirname "$0")/.."
export WGPU_BACKEND="${WGPU_BACKEND:-vulkan}"
mkdir -p target/xdg && chmod 700 target/xdg
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$PWD/target/xdg}"
# Before each cargo command: see scripts/null-device.sh.
bash scripts/null-device.sh
cargo fmt --all -- --check
bash scripts/null-device.sh
cargo clippy --workspace --all-targets --locked -- -D warnings
bash scripts/null-device.sh
cargo test --workspace --locked
