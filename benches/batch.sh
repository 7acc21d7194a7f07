#!/usr/bin/env bash
# Whole trajectories: `mdlod batch` of generated multi-frame LAMMPS text dumps as
# separate processes under /usr/bin/time: every frame from a cold page cache (dropped
# where this user may), the same on one thread, a rerun with nothing to do, a rerun
# and the same from a cold page cache with and without the frame index kept, a rerun
# after a quarter of the frames were deleted, a rerun after the dump grew (half its
# frames converted first, the rest appended) and after it was touched, the two shards of `--shard I/2` one after
# the other and their `--merge`; then many small frames (what a frame costs beyond its
# particles), and their rerun. Writes the table into BENCHMARKS.md between the batch
# markers.
#
#   bash benches/batch.sh          # 20 frames of 10^6 particles, 3000 frames of 2000
#   FRAMES=8 PARTICLES=4000000 MANY_FRAMES=10000 bash benches/batch.sh
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-20}
PARTICLES=${PARTICLES:-1000000}
MANY_FRAMES=${MANY_FRAMES:-3000}
MANY_PARTICLES=${MANY_PARTICLES:-2000}
cargo build --release --bin mdlod >&2
BIN=target/release/mdlod
DIR=data/bench/batch
mkdir -p "$DIR"
# The dump of $2 frames of $1 particles, generated when missing.
dump_of() {
  local path="$DIR/crater-$1-x$2.lammpstrj"
  [ -f "$path" ] || "$BIN" generate crater -n "$1" --frames "$2" -o "$path" >&2
  echo "$path"
}
dump=$(dump_of "$PARTICLES" "$FRAMES")
many=$(dump_of "$MANY_PARTICLES" "$MANY_FRAMES")
out="$DIR/out"
can_drop=no
if [ -w /proc/sys/vm/drop_caches ]; then can_drop=yes; fi
drop() {
  sync
  if [ "$can_drop" = yes ]; then echo 1 > /proc/sys/vm/drop_caches; fi
}
cores=$(nproc)
rows=""
# One run of `mdlod batch ARGS...` on frames of $2 particles: a table row named $1
# (frames converted and skipped from the command's summary line).
run() {
  local name=$1 n=$2
  shift 2
  /usr/bin/time -f "%e %U %S %M %I" -o "$DIR/time.log" "$BIN" batch "$@" > "$DIR/stdout.log" 2> "$DIR/stderr.log" || {
    cat "$DIR/stderr.log" >&2
    exit 1
  }
  local summary converted skipped wall user sys rss blocks
  summary=$(grep -h "converted" "$DIR/stdout.log" "$DIR/stderr.log" | tail -1)
  converted=$(sed -E 's/.* ([0-9]+) converted.*/\1/' <<< "$summary")
  skipped=$(sed -E 's/.* ([0-9]+) already done.*/\1/' <<< "$summary")
  read -r wall user sys rss blocks < "$DIR/time.log"
  rows="$rows
$(python3 benches/batch_row.py "$name" "$n" "$converted" "$skipped" "$wall" "$user" "$sys" "$rss" "$cores" "$blocks")"
}
listed() {
  python3 -c "import json, sys; print(len(json.load(open(sys.argv[1]))['frames']))" "$out/dataset.json"
}
gb() {
  python3 -c "import os, sys; print(f'{os.path.getsize(sys.argv[1]) / 1e9:.2f}')" "$1"
}
radius=(--radius 1=1.28)
N=$PARTICLES
rm -rf "$out"
drop
run "every frame (cold page cache: $can_drop)" "$N" "$dump" -o "$out" "${radius[@]}"
rm -rf "$out"
run "every frame, \`--threads 1\`" "$N" "$dump" -o "$out" "${radius[@]}" --threads 1
run "rerun, nothing changed" "$N" "$dump" -o "$out" "${radius[@]}"
# The same from a cold page cache, with the frame index the runs keep in the directory
# (`.dataset.index.json`) and without it (the dump's every byte read to find its frames).
drop
run "rerun, nothing changed, cold page cache" "$N" "$dump" -o "$out" "${radius[@]}"
rm -f "$out/.dataset.index.json"
drop
run "rerun, nothing changed, cold page cache, no frame index kept" "$N" "$dump" -o "$out" "${radius[@]}"
for f in $(ls "$out"/frame-*.mdlod | sort -V | awk -v q=$((FRAMES / 4)) 'NR % 4 == 0 && n++ < q'); do
  rm "$f"
done
run "rerun after deleting a quarter of the frames" "$N" "$dump" -o "$out" "${radius[@]}"
# A dump a running simulation is still writing: converted with half its frames, then
# rerun once the rest are appended (the old frames' bytes are read and compared), then
# touched (every frame's bytes compared, nothing converted).
half=$((FRAMES / 2))
cut=$(grep -a -b -m $((half + 1)) "^ITEM: TIMESTEP" "$dump" | tail -1 | cut -d: -f1)
growing="$DIR/growing.lammpstrj"
head -c "$cut" "$dump" > "$growing"
rm -rf "$out"
"$BIN" batch "$growing" -o "$out" "${radius[@]}" > /dev/null
tail -c +$((cut + 1)) "$dump" >> "$growing"
run "rerun after the dump grew from $half to $FRAMES frames" "$N" "$growing" -o "$out" "${radius[@]}"
touch "$growing"
run "rerun after \`touch\` (every frame's bytes compared)" "$N" "$growing" -o "$out" "${radius[@]}"
rm -f "$growing"
rm -rf "$out"
run "\`--shard 0/2\`" "$N" "$dump" -o "$out" "${radius[@]}" --shard 0/2
run "\`--shard 1/2\`" "$N" "$dump" -o "$out" "${radius[@]}" --shard 1/2
/usr/bin/time -f "%e" -o "$DIR/time.log" "$BIN" batch --merge "$out" > /dev/null
merge=$(cat "$DIR/time.log")
merged=$(listed)
# A job array's tasks from a cold page cache: each lists the dump's frames by reading
# all of it, unless `--index-only` kept the index first.
rm -rf "$out"
drop
run "\`--shard 0/2\`, cold page cache" "$N" "$dump" -o "$out" "${radius[@]}" --shard 0/2
rm -rf "$out"
drop
/usr/bin/time -f "%e" -o "$DIR/time.log" "$BIN" batch --index-only "$dump" -o "$out" > /dev/null
index_only=$(cat "$DIR/time.log")
drop
run "\`--shard 0/2\`, cold page cache, after \`--index-only\`" "$N" "$dump" -o "$out" "${radius[@]}" --shard 0/2
rm -rf "$out"
run "small frames" "$MANY_PARTICLES" "$many" -o "$out" "${radius[@]}"
run "small frames, rerun" "$MANY_PARTICLES" "$many" -o "$out" "${radius[@]}"
many_listed=$(listed)
rm -rf "$out"
cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')
table="Machine: $cores cores ($cpu). Inputs: LAMMPS text dumps of $FRAMES frames of $PARTICLES crater particles ($(gb "$dump") GB) and of $MANY_FRAMES small frames of $MANY_PARTICLES ($(gb "$many") GB), from \`mdlod generate crater --frames\`, converted with \`mdlod batch --radius 1=1.28\` and the default memory limit; CPU is user + system time; throughput counts converted frames only.

| run | particles a frame | frames converted | frames skipped | wall s | CPU s | frames/s | M particles/s | per core | peak RSS MiB | MB read from disk |
|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|$rows

\`mdlod batch --merge\` of the two shards: $merge s, $merged frames in the joined manifest. \`mdlod batch --index-only\` of the dump from a cold page cache: $index_only s. The small frames' manifest lists $many_listed."
echo "$table"
python3 benches/write_section.py batch "bash benches/batch.sh" "## Timestep batches" "$table"
