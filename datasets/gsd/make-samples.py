#!/usr/bin/env python3
"""Writes the small GSD samples in this folder with the `gsd` package (pip install gsd),
and, for each, an extended XYZ file with the same particles, for the reader tests.

hoomd_mixture.gsd: 300 particles of types A and B in a triclinic box, 3 frames
(steps 0, 100, 200). As HOOMD does, frames 1 and 2 store only what changed (positions,
step, charge); box, types, type ids and diameters come from frame 0. Diameters are 1.0
(A) and 1.5 (B); `particles/charge` is a per-particle scalar.
"""
import numpy as np
import gsd.hoomd

N = 300
BOX = [10.0, 11.0, 12.0, 0.1, 0.2, 0.3]  # Lx Ly Lz xy xz yz

def lattice(box):
    lx, ly, lz, xy, xz, yz = box
    a = np.array([lx, 0, 0])
    b = np.array([xy * ly, ly, 0])
    c = np.array([xz * lz, yz * lz, lz])
    return a, b, c

rng = np.random.default_rng(20261126)
typeid = rng.integers(0, 2, N).astype(np.uint32)
diameter = np.where(typeid == 0, 1.0, 1.5).astype(np.float32)
a, b, c = lattice(BOX)
origin = -(a + b + c) / 2
frac = rng.random((N, 3))
with gsd.hoomd.open("hoomd_mixture.gsd", "w") as f:
    for k in range(3):
        frame = gsd.hoomd.Frame()
        frame.configuration.step = 100 * k
        frame.particles.N = N
        if k == 0:
            frame.configuration.box = BOX
            frame.particles.types = ["A", "B"]
            frame.particles.typeid = typeid
            frame.particles.diameter = diameter
        frac = (frac + 0.01 * rng.standard_normal((N, 3))) % 1.0
        pos = (origin + frac[:, :1] * a + frac[:, 1:2] * b + frac[:, 2:3] * c).astype(np.float32)
        charge = rng.standard_normal(N).astype(np.float32)
        frame.particles.position = pos
        frame.particles.charge = charge
        f.append(frame)
        with open(f"hoomd_mixture.{k}.xyz", "w") as x:
            lat = " ".join(f"{v:.9g}" for v in np.concatenate([a, b, c]))
            org = " ".join(f"{v:.9g}" for v in origin)
            x.write(f"{N}\n")
            x.write(f'Lattice="{lat}" Origin="{org}" Timestep={100 * k} '
                    f"Properties=species:S:1:pos:R:3:charge:R:1\n")
            names = ["A", "B"]
            for i in range(N):
                x.write(f"{names[typeid[i]]} {pos[i, 0]:.9g} {pos[i, 1]:.9g} {pos[i, 2]:.9g} "
                        f"{charge[i]:.9g}\n")
