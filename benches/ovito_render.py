"""Times OVITO's OpenGL renderer on the last frame of a dump at 1280x720.

Usage: python3 benches/ovito_render.py DUMP [REPEATS] [PNG]
Loads the frame first (not timed), then prints one line per repeat: seconds spent in
Viewport.render_image(size=(1280, 720), renderer=OpenGLRenderer()). Exits 3 when OVITO
is not installed.
"""
import sys
import time

try:
    from ovito.io import import_file
    from ovito.vis import OpenGLRenderer, Viewport
except ImportError:
    sys.exit(3)

path = sys.argv[1]
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 3
png = sys.argv[3] if len(sys.argv) > 3 else "/tmp/ovito-render.png"
pipeline = import_file(path)
last = pipeline.source.num_frames - 1
pipeline.compute(last)
pipeline.add_to_scene()
vp = Viewport(type=Viewport.Type.Perspective, camera_dir=(-1, -1, -0.5))
vp.zoom_all()
for _ in range(repeats):
    t0 = time.perf_counter()
    vp.render_image(size=(1280, 720), filename=png, renderer=OpenGLRenderer(), frame=last)
    print(f"{time.perf_counter() - t0:.4f}", flush=True)
