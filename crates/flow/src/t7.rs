//! Importer for the original SPyNet per-layer Torch7 files
//! `modelL{level}_{variant}-{conv}-{weight|bias}.t7` (levels 1.. = coarsest first, convs 1..5,
//! variants `F`, `C`, `K`, `3`, `4`), as used by the public PyTorch port.
//!
//! Each file is one serialised Torch7 object in binary mode: `int32 type` (4 = torch object),
//! `int32 reference index`, the string `"V 1"` (an `int32` length then bytes; absent in pre-versioning
//! files), the class-name string `torch.FloatTensor`, then the tensor header `int32 ndim`,
//! `int64 size[ndim]`, `int64 stride[ndim]`, `int64 storage_offset` (1-based), followed by the storage
//! object (`int32 type`, `int32 index`, version, `torch.FloatStorage`, `int64 count`, `count` little-endian
//! f32 values) or nil (`type 0`). The header is parsed and every offset checked — nothing is assumed
//! about the layout of the data beyond that. These files must never be shipped with the project.

use crate::net::{Conv, KERNEL, LAYER_CHANNELS};
use crate::{FlowError, SpyNet};
use std::path::Path;

/// Most elements a tensor may have (2^28, 1 GiB of f32; SPyNet's largest layer has 50 176).
const MAX_ELEMENTS: usize = 1 << 28;
const TYPE_NIL: i32 = 0;
const TYPE_TORCH: i32 = 4;

struct Reader<'a> {
    name: &'a str,
    bytes: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn err(&self, message: impl Into<String>) -> FlowError {
        FlowError::Torch7 {
            name: self.name.to_string(),
            message: message.into(),
        }
    }
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], FlowError> {
        if self.bytes.len() - self.pos < n {
            return Err(self.err(format!(
                "truncated file: {what} needs {n} bytes at offset {}, only {} left",
                self.pos,
                self.bytes.len() - self.pos
            )));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn int(&mut self, what: &str) -> Result<i32, FlowError> {
        let b = self.take(4, what)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn long(&mut self, what: &str) -> Result<i64, FlowError> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(i64::from_le_bytes(a))
    }
    fn string(&mut self, what: &str) -> Result<String, FlowError> {
        let n = self.int(what)?;
        if !(0..=4096).contains(&n) {
            return Err(self.err(format!("{what}: implausible string length {n}")));
        }
        let b = self.take(n as usize, what)?;
        Ok(String::from_utf8_lossy(b).into_owned())
    }
    /// Reads the object header of a torch object and returns its class name.
    fn torch_header(&mut self, what: &str) -> Result<String, FlowError> {
        let ty = self.int(what)?;
        if ty != TYPE_TORCH {
            return Err(self.err(format!(
                "{what}: expected a torch object (type 4), found type {ty}"
            )));
        }
        let _index = self.int(what)?;
        let first = self.string(what)?;
        if first.starts_with("V ") {
            self.string(what)
        } else {
            Ok(first)
        }
    }
}

/// A tensor read from a Torch7 file: its sizes and its elements in row-major order.
#[derive(Clone, Debug, PartialEq)]
pub struct T7Tensor {
    /// Sizes per dimension.
    pub shape: Vec<usize>,
    /// Elements, contiguous row-major (strides of the file resolved).
    pub data: Vec<f32>,
}

/// Parses one binary Torch7 `torch.FloatTensor` object; `name` is used in error messages.
pub fn parse_float_tensor(bytes: &[u8], name: &str) -> Result<T7Tensor, FlowError> {
    let mut r = Reader {
        name,
        bytes,
        pos: 0,
    };
    let class = r.torch_header("tensor header")?;
    if class != "torch.FloatTensor" {
        return Err(r.err(format!("expected torch.FloatTensor, found class {class:?}")));
    }
    let ndim = r.int("ndim")?;
    if !(0..=8).contains(&ndim) {
        return Err(r.err(format!("implausible ndim {ndim}")));
    }
    let ndim = ndim as usize;
    let mut shape = Vec::with_capacity(ndim);
    for d in 0..ndim {
        let s = r.long("size")?;
        if s < 0 {
            return Err(r.err(format!("negative size {s} in dimension {d}")));
        }
        shape.push(s as usize);
    }
    let mut strides = Vec::with_capacity(ndim);
    for _ in 0..ndim {
        strides.push(r.long("stride")?);
    }
    let offset = r
        .long("storage offset")?
        .checked_sub(1)
        .ok_or_else(|| r.err("implausible storage offset"))?;
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &s| acc.checked_mul(s))
        .filter(|&c| c <= MAX_ELEMENTS)
        .ok_or_else(|| r.err(format!("implausible tensor sizes {shape:?}")))?;
    let storage_type = r.int("storage object")?;
    if storage_type == TYPE_NIL {
        if count == 0 || ndim == 0 {
            return Ok(T7Tensor {
                shape,
                data: Vec::new(),
            });
        }
        return Err(r.err("tensor has elements but no storage"));
    }
    r.pos -= 4;
    let sclass = r.torch_header("storage header")?;
    if sclass != "torch.FloatStorage" {
        return Err(r.err(format!(
            "expected torch.FloatStorage, found class {sclass:?}"
        )));
    }
    let n = r.long("storage count")?;
    if n < 0 {
        return Err(r.err(format!("negative storage count {n}")));
    }
    let n = n as usize;
    let raw = r.take(
        n.checked_mul(4).ok_or_else(|| FlowError::Torch7 {
            name: name.to_string(),
            message: "storage count overflows".into(),
        })?,
        "storage data",
    )?;
    let storage: Vec<f32> = raw
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if count == 0 {
        return Ok(T7Tensor {
            shape,
            data: Vec::new(),
        });
    }
    // Validate the strided view against the storage, then gather row-major.
    // In i128: sizes are at most MAX_ELEMENTS and strides fit i64, so nothing here can overflow.
    let mut max = i128::from(offset);
    for d in 0..ndim {
        if strides[d] < 0 {
            return Err(r.err(format!("negative stride {} in dimension {d}", strides[d])));
        }
        max += (shape[d] as i128 - 1) * i128::from(strides[d]);
    }
    if offset < 0 || max >= n as i128 {
        return Err(r.err(format!(
            "view (offset {offset}, sizes {shape:?}, strides {strides:?}) exceeds storage of {n} values"
        )));
    }
    let mut data = Vec::with_capacity(count);
    let mut idx = vec![0usize; ndim];
    for _ in 0..count {
        let mut p = offset;
        for d in 0..ndim {
            p += idx[d] as i64 * strides[d];
        }
        data.push(storage[p as usize]);
        for d in (0..ndim).rev() {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    Ok(T7Tensor { shape, data })
}

/// File name of one tensor: `modelL{level+1}_{variant}-{conv+1}-{weight|bias}.t7` (`level` and
/// `conv` 0-based here).
pub fn file_name(level: usize, variant: &str, conv: usize, what: &str) -> String {
    format!("modelL{}_{variant}-{}-{what}.t7", level + 1, conv + 1)
}

/// Imports a whole network from a directory of per-layer Torch7 files of one variant. The number of
/// levels is the number of consecutive levels whose first weight file exists (5 or 6 for the
/// published variants). The network runs with the reference pyramid rule the weights were trained
/// and published with ([`crate::PyramidDepth::REFERENCE`]). Errors name the missing, malformed or
/// wrongly shaped file.
pub fn import_dir(dir: &Path, variant: &str) -> Result<SpyNet<f32>, FlowError> {
    let mut levels = 0;
    while dir.join(file_name(levels, variant, 0, "weight")).is_file() {
        levels += 1;
    }
    if levels == 0 {
        return Err(FlowError::MissingTensor {
            name: dir
                .join(file_name(0, variant, 0, "weight"))
                .display()
                .to_string(),
        });
    }
    let mut net = SpyNet::zeros(levels);
    for l in 0..levels {
        let mut convs = Vec::with_capacity(5);
        for (i, &(ci, co)) in LAYER_CHANNELS.iter().enumerate() {
            let read = |what: &str, expected: Vec<usize>| -> Result<Vec<f32>, FlowError> {
                let fname = file_name(l, variant, i, what);
                let path = dir.join(&fname);
                if !path.is_file() {
                    return Err(FlowError::MissingTensor { name: fname });
                }
                let bytes = std::fs::read(&path).map_err(|source| FlowError::Io {
                    path: path.display().to_string(),
                    source,
                })?;
                let t = parse_float_tensor(&bytes, &fname)?;
                // Biases may be stored as (c_out) or (1, c_out): compare element counts and the
                // non-unit dimensions.
                let squeeze =
                    |s: &[usize]| s.iter().copied().filter(|&d| d != 1).collect::<Vec<_>>();
                if squeeze(&t.shape) != squeeze(&expected) {
                    return Err(FlowError::WrongShape {
                        name: fname,
                        expected,
                        actual: t.shape,
                    });
                }
                Ok(t.data)
            };
            let weight = read("weight", vec![co, ci, KERNEL, KERNEL])?;
            let bias = read("bias", vec![co])?;
            convs.push(Conv { weight, bias });
        }
        net.levels[l] = convs;
    }
    Ok(net.with_depth(crate::PyramidDepth::REFERENCE))
}

/// Serialises a tensor as a binary Torch7 `torch.FloatTensor` (contiguous, offset 1, version "V 1").
/// Used by tests to build synthetic files; the layout is exactly what [`parse_float_tensor`] reads.
pub fn write_float_tensor(shape: &[usize], data: &[f32]) -> Vec<u8> {
    let mut b = Vec::new();
    let string = |b: &mut Vec<u8>, s: &str| {
        b.extend_from_slice(&(s.len() as i32).to_le_bytes());
        b.extend_from_slice(s.as_bytes());
    };
    b.extend_from_slice(&TYPE_TORCH.to_le_bytes());
    b.extend_from_slice(&1i32.to_le_bytes());
    string(&mut b, "V 1");
    string(&mut b, "torch.FloatTensor");
    b.extend_from_slice(&(shape.len() as i32).to_le_bytes());
    for &s in shape {
        b.extend_from_slice(&(s as i64).to_le_bytes());
    }
    let mut stride = 1i64;
    let mut strides = vec![0i64; shape.len()];
    for d in (0..shape.len()).rev() {
        strides[d] = stride;
        stride *= shape[d] as i64;
    }
    for s in strides {
        b.extend_from_slice(&s.to_le_bytes());
    }
    b.extend_from_slice(&1i64.to_le_bytes());
    b.extend_from_slice(&TYPE_TORCH.to_le_bytes());
    b.extend_from_slice(&2i32.to_le_bytes());
    string(&mut b, "V 1");
    string(&mut b, "torch.FloatStorage");
    b.extend_from_slice(&(data.len() as i64).to_le_bytes());
    for v in data {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}
