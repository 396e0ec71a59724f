#!/usr/bin/env python3
"""Writes `splat600.ply`, 600 random Gaussians of SH degree 3 in INRIA's 3DGS PLY layout (binary
little-endian, 62 floats per Gaussian), with numpy and a fixed seed. `splat600.compressed.ply` is
that file converted to the PlayCanvas / SuperSplat compressed layout by the format's reference
tool, `@playcanvas/splat-transform` 3.7.0 (MIT, from the npm registry):

    python3 data-fixtures/ply/make_compressed_fixture.py
    npx @playcanvas/splat-transform@3.7.0 data-fixtures/ply/splat600.ply \
        data-fixtures/ply/splat600.compressed.ply

Made by this project from random numbers; same licence as the repository.
"""
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
N = 600

rng = np.random.default_rng(20261126)
names = (["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{i}" for i in range(3)]
         + [f"f_rest_{i}" for i in range(45)] + ["opacity"]
         + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])
data = np.zeros((N, len(names)), dtype="<f4")
col = {n: i for i, n in enumerate(names)}
data[:, 0:3] = rng.uniform(-1.5, 1.5, (N, 3))
data[:, col["f_dc_0"]:col["f_dc_0"] + 3] = rng.uniform(-1.5, 1.5, (N, 3))
data[:, col["f_rest_0"]:col["f_rest_0"] + 45] = rng.uniform(-0.4, 0.4, (N, 45))
data[:, col["opacity"]] = rng.uniform(-4.0, 4.0, N)
data[:, col["scale_0"]:col["scale_0"] + 3] = rng.uniform(-5.0, -2.0, (N, 3))
q = rng.normal(size=(N, 4))
q /= np.linalg.norm(q, axis=1, keepdims=True)
data[:, col["rot_0"]:col["rot_0"] + 4] = q
header = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % N
header += "".join("property float %s\n" % n for n in names) + "end_header\n"
with open(os.path.join(HERE, "splat600.ply"), "wb") as f:
    f.write(header.encode("ascii"))
    f.write(data.tobytes())
