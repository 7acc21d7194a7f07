"""One row of the batch table (`benches/batch.sh`):

    python3 benches/batch_row.py NAME PARTICLES CONVERTED SKIPPED WALL USER SYS RSS_KB CORES IN_BLOCKS

IN_BLOCKS: the file-system reads `/usr/bin/time` counts (%I, 512-byte blocks): what came
from the disk rather than the page cache.
"""
import sys

name, n, conv, skip, wall, user, sys_, rss, cores, blocks = sys.argv[1:11]
n, conv, skip, cores = int(n), int(conv), int(skip), int(cores)
wall, cpu = float(wall), float(user) + float(sys_)
rate = conv * n / wall / 1e6
# Per core of the machine, whatever the run's thread count (`--threads` sets the
# conversions' pool; reading and writing have threads of their own).
print(
    f"| {name} | {n} | {conv} | {skip} | {wall:.2f} | {cpu:.2f} | {conv / wall:.1f} "
    f"| {rate:.2f} | {rate / cores:.2f} | {int(rss) / 1024:.0f} | {int(blocks) * 512 / 1e6:.0f} |"
)
