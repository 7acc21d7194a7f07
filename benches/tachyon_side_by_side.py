"""mdlod's S-NDF image of the real 10^6-atom LAMMPS dump next to OVITO's Tachyon
renderer with antialiasing, the same view: the time each took and each one's error
against its own high-sample reference (mdlod: 64-spp supersampled ray casting; Tachyon:
its own render with many more antialiasing samples; the two renderers shade differently,
so each is measured against itself).

Usage (after `bash datasets/lammps/make-large.sh` and a release build):
    python3 benches/tachyon_side_by_side.py [DUMP] [MDLOD_FILE]
Writes data/bench/tachyon/*.png, docs/images/{cu-large-sndf,cu-large-tachyon}.png and the
`tachyon` section of BENCHMARKS.md. Exits 3 when OVITO is not installed.
"""
import json
import math
import os
import re
import struct
import subprocess
import sys
import time
import zlib

try:
    import numpy as np
    from ovito.io import import_file
    from ovito.vis import TachyonRenderer, Viewport
except ImportError:
    sys.exit(3)

DUMP = sys.argv[1] if len(sys.argv) > 1 else "data/cu_large_1000188.dump"
MDLOD = sys.argv[2] if len(sys.argv) > 2 else "data/cu_large.mdlod"
BIN = "target/release/mdlod"
W, H = 448, 252  # the S-NDFs (8×8 bins) fit one 128 MiB buffer of a software driver
ITERATIONS, SPP_REF = 16, 64
AA, AA_REF = 16, 96
OUT = "data/bench/tachyon"
os.makedirs(OUT, exist_ok=True)


def read_png(path):
    """8-bit RGB(A) PNG, non-interlaced, as an (h, w, 3) float array."""
    data = open(path, "rb").read()
    pos, chunks, ihdr = 8, [], None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            chunks.append(body)
        pos += 12 + n
    w, h, depth, colour = ihdr[0], ihdr[1], ihdr[2], ihdr[3]
    assert depth == 8 and colour in (2, 6), (depth, colour)
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(b"".join(chunks))
    stride = w * bpp
    img = np.zeros((h, stride), dtype=np.int32)
    prev = np.zeros(stride, dtype=np.int32)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = np.frombuffer(raw, dtype=np.uint8, count=stride, offset=y * (stride + 1) + 1).astype(np.int32)
        out = np.zeros(stride, dtype=np.int32)
        if f == 0:
            out = line
        elif f == 2:
            out = (line + prev) & 255
        else:
            for i in range(stride):
                a = out[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                if f == 1:
                    p = a
                elif f == 3:
                    p = (a + b) // 2
                else:
                    pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                    p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                out[i] = (line[i] + p) & 255
        img[y] = out
        prev = out
    return img.reshape(h, w, bpp)[:, :, :3].astype(np.float64)


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def mdlod(args):
    t0 = time.perf_counter()
    out = subprocess.run([BIN, *args], capture_output=True, text=True, check=True).stdout
    return time.perf_counter() - t0, out


view = f"{OUT}/view.json"
common = [MDLOD, "--width", str(W), "--height", str(H)]
t_ref, _ = mdlod(["render", *common, "-o", f"{OUT}/mdlod-ref.png", "--spp", str(SPP_REF),
                  "--azimuth", "45", "--elevation", "20", "--save-view", view])
t_sndf, out = mdlod(["render", *common, "-o", f"{OUT}/mdlod-sndf.png", "--mode", "sndf",
                     "--iterations", str(ITERATIONS), "--view", view])
t_spp, _ = mdlod(["render", *common, "-o", f"{OUT}/mdlod-spp.png", "--spp", str(ITERATIONS),
                  "--view", view])
t_one, _ = mdlod(["render", *common, "-o", f"{OUT}/mdlod-1spp.png", "--view", view])

cam = json.load(open(view))
az, el = math.radians(cam["azimuth_deg"]), math.radians(cam["elevation_deg"])
target = cam["target"]
d = cam["distance"]
eye = [target[0] + d * math.cos(el) * math.cos(az), target[1] + d * math.cos(el) * math.sin(az),
       target[2] + d * math.sin(el)]
pipeline = import_file(DUMP)
last = pipeline.source.num_frames - 1
radius = json.loads(subprocess.run([BIN, "info", MDLOD, "--json"], capture_output=True,
                                   text=True, check=True).stdout)["species"][0]["radius"]


def same_radius(frame, data):
    # The radius mdlod's file gives the atoms.
    data.particles_.vis.radius = radius
    for t in data.particles_.particle_types_.types_:
        t.radius = radius
    if data.cell is not None:
        data.cell_.vis.enabled = False


pipeline.modifiers.append(same_radius)
pipeline.add_to_scene()
vp = Viewport(type=Viewport.Type.Perspective, camera_pos=eye,
              camera_dir=[target[k] - eye[k] for k in range(3)],
              fov=math.radians(cam["fov_y_deg"]))


def tachyon(samples, png):
    t0 = time.perf_counter()
    vp.render_image(size=(W, H), filename=png, frame=last,
                    renderer=TachyonRenderer(antialiasing_samples=samples))
    return time.perf_counter() - t0


t_tach = tachyon(AA, f"{OUT}/tachyon.png")
t_tach_ref = tachyon(AA_REF, f"{OUT}/tachyon-ref.png")

ref = read_png(f"{OUT}/mdlod-ref.png")
tref = read_png(f"{OUT}/tachyon-ref.png")
bg_m = np.all(ref > 250, axis=2)
bg_t = np.all(tref > 250, axis=2)
iou = float(np.sum(~bg_m & ~bg_t) / max(1, np.sum(~bg_m | ~bg_t)))
rows = [
    ("mdlod S-NDF", f"{ITERATIONS} iterations", t_sndf, rmse(read_png(f"{OUT}/mdlod-sndf.png"), ref)),
    ("mdlod ray casting", f"{ITERATIONS} spp", t_spp, rmse(read_png(f"{OUT}/mdlod-spp.png"), ref)),
    ("mdlod ray casting", "1 spp", t_one, rmse(read_png(f"{OUT}/mdlod-1spp.png"), ref)),
    ("OVITO Tachyon", f"{AA} AA samples", t_tach, rmse(read_png(f"{OUT}/tachyon.png"), tref)),
]
adapter = re.search(r" on (.*?) \(", out)
table = (
    f"Machine: {os.cpu_count()} cores; mdlod on **{adapter.group(1) if adapter else '?'}**, "
    f"OVITO {__import__('ovito').version_string} Tachyon on the CPU. The real 10^6-atom EAM copper dump "
    f"(`make-large.sh`), {W}×{H}, one view (silhouette overlap of the two references, "
    f"intersection over union: {iou:.3f}). Times are whole commands for mdlod (process "
    f"start, GPU setup, traversal, sampling, shading, PNG) and `render_image` for OVITO. "
    f"Error: RMSE in 8-bit sRGB levels against each renderer's own reference (mdlod "
    f"{SPP_REF}-spp ray casting, {t_ref:.1f} s; Tachyon with {AA_REF} samples, "
    f"{t_tach_ref:.1f} s).\n\n"
    "| renderer | samples | time s | RMSE vs own reference |\n|---|---|---:|---:|\n"
    + "".join(f"| {r} | {s} | {t:.1f} | {e:.2f} |\n" for r, s, t, e in rows)
)
print(table)
subprocess.run(["cp", f"{OUT}/mdlod-sndf.png", "docs/images/cu-large-sndf.png"], check=True)
subprocess.run(["cp", f"{OUT}/tachyon.png", "docs/images/cu-large-tachyon.png"], check=True)
begin = "<!-- tachyon:begin (generated by `python3 benches/tachyon_side_by_side.py`; do not edit) -->"
end = "<!-- tachyon:end -->"
s = open("BENCHMARKS.md").read()
block = f"{begin}\n{table}{end}"
if begin in s:
    s = re.sub(re.escape(begin) + ".*?" + re.escape(end), lambda m: block, s, flags=re.S)
else:
    s = s.rstrip("\n") + "\n\n## S-NDFs next to OVITO's Tachyon\n\n" + block + "\n"
open("BENCHMARKS.md", "w").write(s)
