"""Times OVITO loading one frame of a dump: import_file(path).compute(frame).

Usage: python3 benches/ovito_load.py FILE [REPEATS]
Prints one line per repeat: seconds. Exits 3 when OVITO is not installed.
"""
import sys
import time

try:
    from ovito.io import import_file
except ImportError:
    sys.exit(3)

path = sys.argv[1]
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 3
for _ in range(repeats):
    t0 = time.perf_counter()
    pipeline = import_file(path)
    data = pipeline.compute(pipeline.source.num_frames - 1)
    n = data.particles.count
    print(f"{time.perf_counter() - t0:.4f} {n}", flush=True)
