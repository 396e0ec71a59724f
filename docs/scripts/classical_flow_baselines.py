"""Classical optical-flow baselines on the flow issue's two test sets.

How good can *any* estimator be on the pairs the project's SPyNet-style network is scored on? This
scores OpenCV's classical estimators (DIS, Farnebäck, TV-L1, DeepFlow) on exactly those pairs and
targets, as the EPE ratio against zero flow (lower is better; the issue's target is <= 0.30):

- the `train-flow` held-out set (40 procedural pairs, 64x64), over all pixels;
- the synthetic benchmark's consecutive pairs at the flow loss's 1/4 resolution, over the loss's
  mask M (|F| > tau, valid), on sharp and on blurred frames;
- the benchmark at full resolution (flow estimated on the 256x256 sharp frames, then resized to the
  loss's target exactly as the target is: align_corners=True bilinear, vectors x 1/4);
- a floor: the full-resolution ground truth read at the nearest source pixel instead of bilinearly
  (how far the loss's resized target is from a physical flow of one surface).

A diagnostic, not part of the build or the tests; OpenCV is not a project dependency. Usage:

    cargo run --release -p train --example export_flow_pairs -- /tmp/pairs target/benchmark/default
    python3 -m venv /tmp/cvenv && /tmp/cvenv/bin/pip install numpy opencv-contrib-python-headless
    /tmp/cvenv/bin/python docs/scripts/classical_flow_baselines.py /tmp/pairs

Images go to the estimators as 8-bit luma (float luma for TV-L1). "x4" runs an estimator on the
pair upsampled 4x (bicubic) and area-averages its flow back, which helps estimators built for
larger images. Figures and the versions used: docs/notes/benchmarks-history.md, flow, "Classical
estimators on the same pairs".
"""

import glob
import json
import sys

import cv2
import numpy as np


def load(path, channels, height, width):
    return np.fromfile(path, dtype="<f4").reshape(channels, height, width)


def luma(img):
    return 0.299 * img[0] + 0.587 * img[1] + 0.114 * img[2]


def luma8(img, up):
    g = np.clip(luma(img) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if up > 1:
        g = cv2.resize(g, (g.shape[1] * up, g.shape[0] * up), interpolation=cv2.INTER_CUBIC)
    return g


def lumaf(img, up):
    g = luma(img).astype(np.float32)
    if up > 1:
        g = cv2.resize(g, (g.shape[1] * up, g.shape[0] * up), interpolation=cv2.INTER_CUBIC)
    return g


def estimator(name, up):
    """A function (img1, img2) -> flow (H, W, 2) for planar RGB images in [0, 1]."""

    def run(a, b):
        h, w = a.shape[1:]
        if name == "dis-medium" or name == "dis-fast":
            preset = {"dis-medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
                      "dis-fast": cv2.DISOPTICAL_FLOW_PRESET_FAST}[name]
            dis = cv2.DISOpticalFlow_create(preset)
            if up == 1 and h <= 64:
                dis.setPatchSize(6)
                dis.setPatchStride(2)
            f = dis.calc(luma8(a, up), luma8(b, up), None)
        elif name == "farneback":
            f = cv2.calcOpticalFlowFarneback(luma8(a, up), luma8(b, up), None, 0.5, 5,
                                             9 if up > 1 else 5, 5, 5, 1.1, 0)
        elif name == "tvl1":
            f = cv2.optflow.DualTVL1OpticalFlow_create().calc(lumaf(a, up), lumaf(b, up), None)
        elif name == "deepflow":
            f = cv2.optflow.createOptFlow_DeepFlow().calc(luma8(a, up), luma8(b, up), None)
        else:
            raise ValueError(name)
        if up > 1:
            f = cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) / up
        return f

    return run


ESTIMATORS = [(n, up) for n in ("dis-medium", "dis-fast", "farneback", "tvl1", "deepflow")
              for up in (1, 4)]


def epe(f, g):
    return np.sqrt(((f - g) ** 2).sum(-1))


def held_out(root, size):
    stems = sorted(p[: -len("_img1.f32")] for p in glob.glob(f"{root}/heldout/*_img1.f32"))
    for name, up in ESTIMATORS:
        run = estimator(name, up)
        net = zero = 0.0
        for s in stems:
            a, b = load(s + "_img1.f32", 3, size, size), load(s + "_img2.f32", 3, size, size)
            truth = load(s + "_flow.f32", 2, size, size).transpose(1, 2, 0)
            net += epe(run(a, b), truth).sum()
            zero += np.sqrt((truth ** 2).sum(-1)).sum()
        print(f"held-out  {name:>10} x{up}: EPE {net / (len(stems) * size * size):.3f} px, "
              f"zero {zero / (len(stems) * size * size):.3f}, ratio {net / zero:.3f}", flush=True)


def bench_stems(root):
    return sorted(p[: -len("_flow.f32")] for p in glob.glob(f"{root}/bench/*_flow.f32"))


def bench_quarter(root, h, w):
    for name, up in ESTIMATORS:
        run = estimator(name, up)
        for tag in ("sharp", "blur"):
            net = zero = 0.0
            for s in bench_stems(root):
                a, b = load(s + f"_{tag}1.f32", 3, h, w), load(s + f"_{tag}2.f32", 3, h, w)
                truth = load(s + "_flow.f32", 2, h, w).transpose(1, 2, 0)
                m = load(s + "_mask.f32", 1, h, w)[0] > 0.5
                net += epe(run(a, b), truth)[m].sum()
                zero += np.sqrt((truth ** 2).sum(-1))[m].sum()
            print(f"benchmark 1/4 {tag:>5} {name:>10} x{up}: ratio over M {net / zero:.3f}",
                  flush=True)


def align_corners_grid(h, w, full_h, full_w):
    """Source coordinates the align_corners=True resize samples, as cv2.remap maps."""
    ys = np.arange(h) * (full_h - 1) / max(h - 1, 1)
    xs = np.arange(w) * (full_w - 1) / max(w - 1, 1)
    mx, my = np.meshgrid(xs, ys)
    return mx.astype(np.float32), my.astype(np.float32), xs, ys


def bench_full(root, h, w, full_h, full_w):
    mx, my, xs, ys = align_corners_grid(h, w, full_h, full_w)
    scale = np.array([w / full_w, h / full_h], dtype=np.float32)
    for name in ("dis-medium", "deepflow"):
        run = estimator(name, 1)
        net = zero = 0.0
        for s in bench_stems(root):
            a = load(s + "_full1.f32", 3, full_h, full_w)
            b = load(s + "_full2.f32", 3, full_h, full_w)
            truth = load(s + "_flow.f32", 2, h, w).transpose(1, 2, 0)
            m = load(s + "_mask.f32", 1, h, w)[0] > 0.5
            f = cv2.remap(run(a, b), mx, my, cv2.INTER_LINEAR) * scale
            net += epe(f, truth)[m].sum()
            zero += np.sqrt((truth ** 2).sum(-1))[m].sum()
        print(f"benchmark full resolution {name:>10}: ratio over M {net / zero:.3f}", flush=True)
    # The floor: the full-resolution truth read at the nearest source pixel (a physical flow).
    iy, ix = np.rint(ys).astype(int), np.rint(xs).astype(int)
    err = zero = 0.0
    for s in bench_stems(root):
        full = load(s + "_fullflow.f32", 2, full_h, full_w).transpose(1, 2, 0)
        truth = load(s + "_flow.f32", 2, h, w).transpose(1, 2, 0)
        m = load(s + "_mask.f32", 1, h, w)[0] > 0.5
        err += epe(full[iy][:, ix] * scale, truth)[m].sum()
        zero += np.sqrt((truth ** 2).sum(-1))[m].sum()
    print(f"benchmark floor (nearest-pixel truth vs the loss's target): ratio over M {err / zero:.3f}")


def main():
    root = sys.argv[1]
    with open(f"{root}/pairs.json") as f:
        sizes = json.load(f)
    print(f"OpenCV {cv2.__version__}, NumPy {np.__version__}")
    held_out(root, sizes["heldout"]["size"])
    if "bench" in sizes:
        b = sizes["bench"]
        bench_quarter(root, b["height"], b["width"])
        bench_full(root, b["height"], b["width"], b["full_height"], b["full_width"])


if __name__ == "__main__":
    main()
