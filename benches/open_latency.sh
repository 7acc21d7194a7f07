#!/usr/bin/env bash
# First image of a large file: `mdlod render` (open, adapter, traversal, drawing, PNG)
# of data/bench/crater-<n>.mdlod as a separate process under /usr/bin/time, from a cold
# page cache (dropped before the run, where this user may) and again warm, at several
# screen errors; then `mdlod info` (open alone). Writes the table into BENCHMARKS.md
# between the open-latency markers.
#
#   bash benches/open_latency.sh                        # the 2e8 file, errors 1 4 16
#   SIZES="2000000 200000000" ERRORS="1 16" bash benches/open_latency.sh
#
# The files are the render benchmark's (`cargo bench --bench render` converts them when
# missing; BENCHMARKS.md says how the 2e8 one was made).
set -euo pipefail
cd "$(dirname "$0")/.."
SIZES=${SIZES:-200000000}
ERRORS=${ERRORS:-1 4 16}
cargo build --release --bin mdlod >&2
BIN=target/release/mdlod
OUT=data/bench/open-latency
mkdir -p "$OUT"
can_drop=no
if [ -w /proc/sys/vm/drop_caches ]; then can_drop=yes; fi
drop() {
  sync
  if [ "$can_drop" = yes ]; then echo 1 > /proc/sys/vm/drop_caches; fi
}
# Prints "wall_s rss_mib" of one run of the command after `--`.
timed() {
  /usr/bin/time -f "%e %M" -o "$OUT/time.log" "$@" > /dev/null 2> "$OUT/stderr.log" || {
    cat "$OUT/stderr.log" >&2
    exit 1
  }
  awk '{printf "%s %.0f\n", $1, $2/1024}' "$OUT/time.log"
}
rows=""
for n in $SIZES; do
  file="data/bench/crater-$n.mdlod"
  [ -f "$file" ] || { echo "missing $file (cargo bench --bench render converts it)" >&2; exit 1; }
  gb=$(python3 -c "import os; print(f'{os.path.getsize(\"$file\")/1e9:.1f}')")
  drop
  read -r cold rss_cold < <(timed "$BIN" info "$file")
  read -r warm rss_warm < <(timed "$BIN" info "$file")
  rows="$rows
| $n | $gb | \`info\` (open alone) | $cold | $warm | $rss_cold |"
  for e in $ERRORS; do
    drop
    read -r cold rss_cold < <(timed "$BIN" render "$file" -o "$OUT/r.png" --screen-error "$e")
    read -r warm rss_warm < <(timed "$BIN" render "$file" -o "$OUT/r.png" --screen-error "$e")
    rows="$rows
| $n | $gb | \`render --screen-error $e\` | $cold | $warm | $rss_cold |"
  done
done
cores=$(nproc)
cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')
table="Machine: $cores cores ($cpu). Whole processes at 1280×720 (the defaults), the view fitting the data set; cold: page cache dropped before the run ($can_drop), warm: the same command again. Peak RSS of the cold run.

| particles | .mdlod GB | command | cold s | warm s | peak RSS MiB |
|---:|---:|---|---:|---:|---:|$rows"
echo "$table"
python3 benches/write_section.py open-latency "bash benches/open_latency.sh" "## First image of a large file" "$table"
