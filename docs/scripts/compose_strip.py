#!/usr/bin/env python3
"""Compose a comparison picture for the docs from the panels of `eval` strips.

A strip written by `cargo xtask reconstruct` / `eval` (`<out>/eval/strip_NNNNNN.png`) is four
256-pixel panels separated by 2-pixel gaps: blurred input | render | sharp reference | human
probability. This script takes panels out of one or more strips, in order, and lays them side by
side with the same gaps.

    python3 docs/scripts/compose_strip.py OUT.png STRIP:PANEL [STRIP:PANEL ...]

Example (the deblurring picture of docs/BENCHMARKS.md):

    python3 docs/scripts/compose_strip.py docs/img/quick_deblur_test_frame_8.png \
        RUN_EXPOSURE/eval/strip_000008.png:0 RUN_PAPER/eval/strip_000008.png:1 \
        RUN_EXPOSURE/eval/strip_000008.png:1 RUN_EXPOSURE/eval/strip_000008.png:2

Needs Pillow. Panels are 0-based.
"""
import sys

from PIL import Image

GAP = 2


def panel(path: str, index: int) -> Image.Image:
    strip = Image.open(path).convert("RGB")
    side = strip.height
    left = index * (side + GAP)
    if left + side > strip.width:
        raise SystemExit(f"{path}: no panel {index} (width {strip.width})")
    return strip.crop((left, 0, left + side, side))


def main() -> None:
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    panels = []
    for arg in sys.argv[2:]:
        path, _, index = arg.rpartition(":")
        panels.append(panel(path, int(index)))
    side = panels[0].height
    out = Image.new("RGB", (len(panels) * side + (len(panels) - 1) * GAP, side), "white")
    for k, p in enumerate(panels):
        out.paste(p, (k * (side + GAP), 0))
    out.save(sys.argv[1])


if __name__ == "__main__":
    main()
