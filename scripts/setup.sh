#!/usr/bin/env bash
# Installs what mdlod needs on a fresh Debian/Ubuntu machine that has Rust (cargo) already:
# Mesa's software Vulkan driver (lavapipe), so the renderer and its tests run without a GPU,
# Xvfb, a virtual X display for the viewer's window tests, a C compiler with make for
# jemalloc, the allocator the mdlod binary is built with, and Python 3 with its xxhash
# module for format/spec/read_mdlod.py, the Python reader FORMAT.md is tested against
# (tests/format_spec.rs).
set -euo pipefail
packages=(mesa-vulkan-drivers libvulkan1 xvfb gcc make python3 python3-xxhash)
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi
command -v cargo >/dev/null || { echo "cargo not found: install Rust first (https://rustup.rs)" >&2; exit 1; }
echo "mdlod: system packages ready"
