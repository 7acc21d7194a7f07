#!/usr/bin/env bash
# Generates a ~10^6-atom real LAMMPS dump for benchmarks into data/ at the repository root
# (git-ignored). Usage: datasets/lammps/make-large.sh [CELLS] [STEPS]
#   CELLS (default 63): edge of the FCC block in unit cells; atoms = 4 * CELLS^3
#   STEPS (default 10): MD steps; frames are written at step 0 and step STEPS.
# Output: data/cu_large_<atoms>.dump (dump custom: id type x y z c_pe).
# Needs Debian's `lammps` package (apt-get install -y lammps).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
cells="${1:-63}"
steps="${2:-10}"
atoms=$((4 * cells * cells * cells))
mkdir -p "$root/data"
out="$root/data/cu_large_${atoms}.dump"
export LAMMPS_POTENTIALS="${LAMMPS_POTENTIALS:-/usr/share/lammps/potentials}"
export OMP_NUM_THREADS=1
LMP="${LMP:-$(command -v lmp || command -v lmp_serial)}"
start=$(date +%s)
cd "$here"
"$LMP" -in in.cu_large -var cells "$cells" -var steps "$steps" -var out "$out" \
    -log none -screen none
end=$(date +%s)
echo "$out: $atoms atoms, $(du -h "$out" | cut -f1), $((end - start)) s"
