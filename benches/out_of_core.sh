#!/usr/bin/env bash
# Out-of-core conversion at scale: generates raw-array inputs (cached in data/bench/ooc),
# converts each with `mdlod convert --memory-limit`, and records wall time, throughput,
# peak resident memory (/usr/bin/time) and peak working-file disk (polled), then writes
# the table into BENCHMARKS.md between the out-of-core markers.
#
#   bash benches/out_of_core.sh                 # 2e8 and 1e9 particles, --memory-limit 4G
#   SIZES=20000000 LIMIT=2G bash benches/out_of_core.sh
#
# Disk: about 13 + 2 × 29 bytes per particle at the peak (input, working files, output;
# 1e9 needs about 50 GB free). The 1e9 input has no attribute column to save 4 GB.
set -euo pipefail
cd "$(dirname "$0")/.."
SIZES=${SIZES:-200000000 1000000000}
LIMIT=${LIMIT:-4G}
DIR=data/bench/ooc
mkdir -p "$DIR"
cargo build --release --bin mdlod >&2
BIN=target/release/mdlod
cores=$(nproc)
for n in $SIZES; do
  input="$DIR/crater-$n.raw.json"
  if [ ! -f "$input" ]; then
    "$BIN" generate crater -n "$n" --format raw -o "$input" >&2
    if [ "$n" -ge 1000000000 ]; then
      rm -f "$DIR/crater-$n.c_ke.f32"
      python3 - "$input" <<'PY'
import json, sys
p = sys.argv[1]; d = json.load(open(p)); d.pop("attribute", None); json.dump(d, open(p, "w"), indent=2)
PY
    fi
  fi
  in_bytes=$(du -cb "$DIR"/crater-"$n".* | tail -1 | cut -f1)
  out="$DIR/crater-$n.mdlod"
  rm -f "$out"
  sync
  # Every size starts from a cold page cache where this user may drop it (root), so
  # that the input is read from the disk as in a first conversion.
  cold=no
  if [ -w /proc/sys/vm/drop_caches ] && echo 1 > /proc/sys/vm/drop_caches 2>/dev/null; then
    cold=yes
  fi
  peak_tmp=0
  /usr/bin/time -v "$BIN" convert "$input" -o "$out" --radius 1=1.28 --memory-limit "$LIMIT" \
    >"$DIR/convert-$n.log" 2>"$DIR/time-$n.log" &
  pid=$!
  while kill -0 "$pid" 2>/dev/null; do
    t=$({ du -sb "$DIR"/.mdlod-convert-* 2>/dev/null || true; } | awk '{s+=$1} END {printf "%.0f\n", s}')
    [ "$t" -gt "$peak_tmp" ] && peak_tmp=$t
    sleep 1
  done
  wait "$pid"
  wall=$(grep "Elapsed (wall clock)" "$DIR/time-$n.log" | awk '{print $NF}' | awk -F: '{ if (NF==3) print $1*3600+$2*60+$3; else print $1*60+$2 }')
  rss_kib=$(grep "Maximum resident" "$DIR/time-$n.log" | awk '{print $NF}')
  line=$(grep "^  read" "$DIR/convert-$n.log")
  read_s=$(echo "$line" | sed -E 's/.*read ([0-9.]+) s.*/\1/')
  build_s=$(echo "$line" | sed -E 's/.*hierarchy ([0-9.]+) s.*/\1/')
  write_s=$(echo "$line" | sed -E 's/.*write ([0-9.]+) s.*/\1/')
  err=$(grep "^wrote" "$DIR/convert-$n.log" | sed -E 's/.*max position error (.*)/\1/')
  levels=$(grep "^wrote" "$DIR/convert-$n.log" | sed -E 's/.*particles, ([0-9]+) levels.*/\1/')
  out_bytes=$(stat -c %s "$out")
  "$BIN" verify "$out" >&2
  # Each size's row is kept, so rerunning one size keeps the others' rows.
  echo "$(python3 -c "
n=$n; wall=$wall; c=$cores
print(f'| {n:.1e} | {${in_bytes}/1e9:.1f} | $LIMIT | {wall:.0f} | $read_s | $build_s | $write_s | {n/wall/1e6:.2f} | {n/wall/1e6/c:.2f} | {${rss_kib}/1048576:.2f} | {${peak_tmp}/1e9:.1f} | {${out_bytes}/1e9:.1f} | $levels | $err |')
")" > "$DIR/row-$n.md"
  rm -f "$out"
done
cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')
mem=$(awk '/MemTotal/ {printf "%.0f", $2/1048576}' /proc/meminfo)
table="Machine: $cores cores ($cpu), $mem GiB RAM. Input: generated crater as raw arrays (\`mdlod generate --format raw\`), \`mdlod convert --memory-limit $LIMIT\`, one run each; page cache dropped before each run: $cold.

| particles | input GB | limit | wall s | partition s | chunks s | assembly s | M particles/s | per core | peak RSS GiB | peak working files GB | .mdlod GB | levels | max position error |
|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
for f in $(ls "$DIR"/row-*.md | sort -t- -k2 -n); do table="$table
$(cat "$f")"; done
echo "$table"
python3 benches/write_section.py out-of-core "bash benches/out_of_core.sh" "## Out-of-core conversion" "$table"
