#!/usr/bin/env bash
# Regenerates the small real LAMMPS dumps in this folder (seconds in all).
# Needs Debian's `lammps` package (apt-get install -y lammps), which provides `lmp` and
# the EAM potentials in /usr/share/lammps/potentials.
set -euo pipefail
cd "$(dirname "$0")"
export LAMMPS_POTENTIALS="${LAMMPS_POTENTIALS:-/usr/share/lammps/potentials}"
export OMP_NUM_THREADS=1
LMP="${LMP:-$(command -v lmp || command -v lmp_serial)}"
for input in in.cu_melt in.cuag_alloy in.lj_triclinic in.cu_slab in.cu_melt_binary in.lj_triclinic_binary in.granular in.cu_gb; do
    echo "== $LMP -in $input"
    "$LMP" -in "$input" -log none -screen none
done
# Per-processor pieces need 2 MPI processes (Debian's lmp is built with MPI).
if command -v mpirun >/dev/null; then
    echo "== mpirun -np 2 $LMP -in in.cu_melt_mpi"
    mpirun --allow-run-as-root -np 2 "$LMP" -in in.cu_melt_mpi -log none -screen none
fi
ls -l ./*.dump ./*.dump.gz ./*.xyz ./*.bin
