#!/usr/bin/env python3
"""Compose a comparison picture for the docs from the panels of `eval` strips.

A strip written by `cargo xtask reconstruct` / `eval` (`<out>/eval/strip_NNNNNN.png`) is four
256-pixel panels separated by 2-pixel gaps: blurred input | render | sharp reference | human
probability. This script takes panels out of one or more strips, in order, and lays them side by
side with the same gaps, optionally cropped to one region (pixels of the panel) and enlarged.

    python3 docs/scripts/compose_strip.py OUT.png [--crop X,Y,W,H] [--zoom K] STRIP:PANEL [...]

Example (the deblurring picture of docs/BENCHMARKS.md):

    python3 docs/scripts/compose_strip.py docs/img/quick_deblur_test_frame_8.png \
        RUN_EXPOSURE/eval/strip_000008.png:0 RUN_PAPER/eval/strip_000008.png:1 \
        RUN_EXPOSURE/eval/strip_000008.png:1 RUN_EXPOSURE/eval/strip_000008.png:2

Panels are 0-based. Standard library only (8-bit grey / RGB / RGBA PNG, not interlaced).
"""
import struct
import sys
import zlib

GAP = 2
CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}


class Picture:
    """An 8-bit RGB picture: `rows[y]` is a bytearray of 3·width bytes."""

    def __init__(self, width: int, height: int, rows: list):
        self.width, self.height, self.rows = width, height, rows

    @staticmethod
    def blank(width: int, height: int) -> "Picture":
        return Picture(width, height, [bytearray(b"\xff" * 3 * width) for _ in range(height)])

    def crop(self, x: int, y: int, w: int, h: int) -> "Picture":
        if x < 0 or y < 0 or x + w > self.width or y + h > self.height:
            raise SystemExit(f"crop {x},{y},{w},{h} outside a {self.width}x{self.height} panel")
        return Picture(w, h, [bytearray(r[3 * x : 3 * (x + w)]) for r in self.rows[y : y + h]])

    def zoom(self, k: int) -> "Picture":
        rows = []
        for r in self.rows:
            wide = bytearray()
            for i in range(0, len(r), 3):
                wide += r[i : i + 3] * k
            rows.extend(bytearray(wide) for _ in range(k))
        return Picture(self.width * k, self.height * k, rows)

    def paste(self, other: "Picture", left: int) -> None:
        for y in range(other.height):
            self.rows[y][3 * left : 3 * (left + other.width)] = other.rows[y]


def paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


def read_png(path: str) -> Picture:
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise SystemExit(f"{path}: not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    if header is None:
        raise SystemExit(f"{path}: no IHDR")
    width, height, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in CHANNELS or interlace:
        raise SystemExit(f"{path}: only 8-bit, non-interlaced grey/RGB/RGBA PNGs are read")
    bpp = CHANNELS[colour]
    raw, stride, prev, rows = zlib.decompress(idat), width * bpp, bytearray(width * bpp), []
    for y in range(height):
        start = y * (stride + 1)
        kind, line = raw[start], bytearray(raw[start + 1 : start + 1 + stride])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], (prev[i - bpp] if i >= bpp else 0)
            line[i] = (line[i] + (0, a, b, (a + b) // 2, paeth(a, b, c))[kind]) & 0xFF
        rows.append(to_rgb(line, bpp))
        prev = line
    return Picture(width, height, rows)


def to_rgb(line: bytearray, bpp: int) -> bytearray:
    if bpp == 3:
        return bytearray(line)
    out = bytearray()
    for i in range(0, len(line), bpp):
        out += bytes([line[i]] * 3) if bpp <= 2 else line[i : i + 3]
    return out


def write_png(path: str, picture: Picture) -> None:
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    raw = b"".join(b"\x00" + bytes(r) for r in picture.rows)
    header = struct.pack(">IIBBBBB", picture.width, picture.height, 8, 2, 0, 0, 0)
    with open(path, "wb") as out:
        out.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header))
        out.write(chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def panel(path: str, index: int) -> Picture:
    strip = read_png(path)
    side = strip.height
    left = index * (side + GAP)
    if left + side > strip.width:
        raise SystemExit(f"{path}: no panel {index} (width {strip.width})")
    return strip.crop(left, 0, side, side)


def main() -> None:
    args, crop, zoom = sys.argv[1:], None, 1
    if len(args) < 2:
        raise SystemExit(__doc__)
    out_path, rest, specs = args[0], args[1:], []
    while rest:
        arg = rest.pop(0)
        if arg == "--crop":
            crop = [int(v) for v in rest.pop(0).split(",")]
        elif arg == "--zoom":
            zoom = int(rest.pop(0))
        else:
            specs.append(arg)
    panels = []
    for spec in specs:
        path, _, index = spec.rpartition(":")
        p = panel(path, int(index))
        panels.append((p.crop(*crop) if crop else p).zoom(zoom))
    height = panels[0].height
    out = Picture.blank(sum(p.width for p in panels) + (len(panels) - 1) * GAP, height)
    left = 0
    for p in panels:
        out.paste(p, left)
        left += p.width + GAP
    write_png(out_path, out)


if __name__ == "__main__":
    main()
