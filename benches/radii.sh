#!/usr/bin/env bash
# Particles of their own sizes: what keeping each particle's radius costs. A jittered
# lattice of grains of two types with log-normal radii, as a LAMMPS text dump with a
# `radius` column, converted as it is (each grain's radius kept: format 1.1) and with
# `--radius` giving each type one radius (the same parse; no RADIUS section), each file
# then rendered at 1280x720 (spheres, 1 px error, the whole packing in view). The two
# alternate, REPEATS times; medians. Separate processes under /usr/bin/time. Writes the
# table into BENCHMARKS.md between the radii markers.
#
#   bash benches/radii.sh                      # 6×10^6 grains (a chunked build)
#   PARTICLES=1000000 REPEATS=5 bash benches/radii.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PARTICLES=${PARTICLES:-6000000}
REPEATS=${REPEATS:-3}
cargo build --release --bin mdlod >&2
BIN=target/release/mdlod
DIR=data/bench/radii
mkdir -p "$DIR"
dump="$DIR/grains-$PARTICLES.lammpstrj"
if [ ! -f "$dump" ]; then
  python3 - "$PARTICLES" > "$dump" <<'EOF'
import math, random, sys
n = int(sys.argv[1])
random.seed(7)
side = math.ceil(n ** (1 / 3))
a = 2.0
out = sys.stdout
out.write(f"ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n{n}\nITEM: BOX BOUNDS pp pp ff\n")
for _ in range(3):
    out.write(f"0 {side * a}\n")
out.write("ITEM: ATOMS id type radius x y z\n")
lines = []
for i in range(n):
    x, y, z = i % side, (i // side) % side, i // (side * side)
    t = 2 if random.random() < 0.2 else 1
    r = min(0.95, random.lognormvariate(math.log(0.5 if t == 1 else 0.8), 0.15))
    j = [random.uniform(-0.02, 0.02) for _ in range(3)]
    lines.append(f"{i + 1} {t} {r:.5f} {a * x + j[0]:.4f} {a * y + j[1]:.4f} {a * z + j[2]:.4f}\n")
    if len(lines) >= 100000:
        out.write("".join(lines))
        lines = []
out.write("".join(lines))
EOF
fi
median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }
declare -A conv rss render drawn size
variants=(own one)
for _ in $(seq "$REPEATS"); do
  for v in "${variants[@]}"; do
    extra=()
    if [ "$v" = one ]; then extra=(--radius 1=0.5 --radius 2=0.8); fi
    out="$DIR/$v.mdlod"
    /usr/bin/time -f "%e %M" -o "$DIR/time.log" "$BIN" convert "$dump" -o "$out" "${extra[@]}" > /dev/null
    read -r wall kib < "$DIR/time.log"
    conv[$v]+="$wall "
    rss[$v]+="$((kib / 1024)) "
    size[$v]=$(stat -c %s "$out")
    report=$("$BIN" render "$out" -o "$DIR/$v.png" --width 1280 --height 720 --screen-error 1 --azimuth 30 --elevation 25 2>&1)
    ms=$(echo "$report" | grep -o 'total [0-9.]* ms' | grep -o '[0-9.]*')
    render[$v]+="$ms "
    drawn[$v]=$(echo "$report" | grep -o '[0-9]* particles and [0-9]* cluster spheres' | head -1)
  done
done
cores=$(nproc)
cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')
adapter=$("$BIN" render "$DIR/own.mdlod" -o "$DIR/probe.png" --width 8 --height 8 2>&1 | grep -o ' on .*(\(Vulkan\|Metal\|Dx12\|Gl\))' | head -1 | sed 's/^ on //')
rows=""
for v in "${variants[@]}"; do
  name=$([ "$v" = own ] && echo "each grain its own radius (1.1)" || echo "\`--radius\`: one radius a type (1.0)")
  c=$(echo "${conv[$v]}" | tr ' ' '\n' | grep . | median)
  m=$(echo "${rss[$v]}" | tr ' ' '\n' | grep . | median)
  r=$(echo "${render[$v]}" | tr ' ' '\n' | grep . | median)
  rows+="
| $name | $(awk -v b="${size[$v]}" 'BEGIN {printf "%.1f", b / 1e6}') | $c | $m | $r | ${drawn[$v]} |"
  eval "c_$v=$c; r_$v=$r"
done
ratio() { awk -v a="$1" -v b="$2" 'BEGIN {printf "%.2f", a / b}'; }
table="Machine: $cores cores ($cpu); adapter: $adapter. Input: $PARTICLES grains of two types (a fifth large) on a jittered lattice, log-normal radii, as a LAMMPS text dump with a \`radius\` column ($(awk -v b="$(stat -c %s "$dump")" 'BEGIN {printf "%.2f", b / 1e9}') GB); medians of $REPEATS alternated runs; convert from the page cache.

| file | MB | convert s | peak RSS MiB | render ms (1280x720, 1 px) | drawn |
|---|---:|---:|---:|---:|---|$rows

Own radii against one a type: conversion $(ratio "$c_own" "$c_one")×, render $(ratio "$r_own" "$r_one")×."
echo "$table"
python3 benches/write_section.py radii "bash benches/radii.sh" "## Particles of their own sizes" "$table"
