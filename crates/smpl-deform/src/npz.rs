//! Reading and writing `.npz` body files.
//!
//! Reading validates every array before it is trusted: the shape is checked against what the key
//! must hold *before* the data is read (so no allocation is sized by an unchecked header), dtypes are
//! limited to little/big-endian f32/f64 (floats) and i32/i64/u32/u64 (indices), Fortran-ordered
//! arrays are transposed to C order, and non-finite values are rejected with the key and index.
//! Writing uses a fixed zip timestamp (1980-01-01) so the same arrays always give the same bytes.

use std::collections::HashSet;
use std::io::{Read, Seek, Write};
use std::path::Path;

use npyz::npz::NpzArchive;
use npyz::{DType, Order, TypeChar, WriterBuilder};

use crate::error::{Result, SmplDeformError};

/// Upper bound on the number of elements of any one array (2^28 ≈ 268 M, about 1 GiB of f32);
/// SMPL's largest array (posedirs) has 4.3 M.
pub const MAX_ELEMENTS: u64 = 1 << 28;

/// An open `.npz` archive with validated reads.
pub struct NpzReader<R: Read + Seek> {
    archive: NpzArchive<R>,
    names: HashSet<String>,
}

impl NpzReader<std::io::BufReader<std::fs::File>> {
    /// Opens an `.npz` file.
    pub fn open(path: &Path) -> Result<Self> {
        let archive = NpzArchive::open(path).map_err(|source| SmplDeformError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Self::from_archive(archive))
    }
}

impl<R: Read + Seek> NpzReader<R> {
    /// Wraps any seekable reader holding an `.npz`.
    pub fn new(reader: R) -> Result<Self> {
        let archive = NpzArchive::new(reader).map_err(|e| SmplDeformError::BadArray {
            key: "<archive>".into(),
            message: e.to_string(),
        })?;
        Ok(Self::from_archive(archive))
    }

    fn from_archive(archive: NpzArchive<R>) -> Self {
        let names = archive.array_names().map(str::to_string).collect();
        Self { archive, names }
    }

    /// True when the archive holds an array called `key`.
    pub fn has(&self, key: &str) -> bool {
        self.names.contains(key)
    }

    /// Reads a float array (f32 or f64 on disk, returned as f64 in C order) after checking its shape
    /// with `shape_ok` (`expected` describes the accepted shapes for the error message).
    pub fn read_float(
        &mut self,
        key: &str,
        shape_ok: impl Fn(&[u64]) -> bool,
        expected: &str,
    ) -> Result<(Vec<u64>, Vec<f64>)> {
        let (shape, order, kind, bytes, descr) = self.header(key, &shape_ok, expected)?;
        if !matches!((kind, bytes), (TypeChar::Float, 4 | 8)) {
            return Err(bad_dtype(key, descr));
        }
        let npy = self.open_entry(key)?;
        let data: Vec<f64> = if bytes == 4 {
            read_all::<f32, _>(key, npy)?
                .into_iter()
                .map(f64::from)
                .collect()
        } else {
            read_all::<f64, _>(key, npy)?
        };
        let data = to_c_order(data, &shape, order);
        if let Some(index) = data.iter().position(|v| !v.is_finite()) {
            return Err(SmplDeformError::NonFinite {
                key: key.into(),
                index,
            });
        }
        Ok((shape, data))
    }

    /// Reads an integer array (i32/i64/u32/u64, or integral floats) as i64 in C order. Unsigned
    /// values ≥ 2^31 that equal `u32::MAX` are mapped to −1 (SMPL's root-parent marker).
    pub fn read_int(
        &mut self,
        key: &str,
        shape_ok: impl Fn(&[u64]) -> bool,
        expected: &str,
    ) -> Result<(Vec<u64>, Vec<i64>)> {
        let (shape, order, kind, bytes, descr) = self.header(key, &shape_ok, expected)?;
        if kind == TypeChar::Float && (bytes == 4 || bytes == 8) {
            let (_, f) = self.read_float(key, &shape_ok, expected)?;
            let mut out = Vec::with_capacity(f.len());
            for (index, v) in f.into_iter().enumerate() {
                if v.fract() != 0.0 || v.abs() > 1e15 {
                    return Err(SmplDeformError::BadArray {
                        key: key.into(),
                        message: format!("non-integral index value {v} at flat index {index}"),
                    });
                }
                out.push(if v == f64::from(u32::MAX) {
                    -1
                } else {
                    v as i64
                });
            }
            return Ok((shape, out));
        }
        if !matches!((kind, bytes), (TypeChar::Int | TypeChar::Uint, 4 | 8)) {
            return Err(bad_dtype(key, descr));
        }
        let npy = self.open_entry(key)?;
        let data: Vec<i64> = match (kind, bytes) {
            (TypeChar::Int, 4) => read_all::<i32, _>(key, npy)?
                .into_iter()
                .map(i64::from)
                .collect(),
            (TypeChar::Int, 8) => read_all::<i64, _>(key, npy)?,
            (TypeChar::Uint, 4) => read_all::<u32, _>(key, npy)?
                .into_iter()
                .map(|v| if v == u32::MAX { -1 } else { i64::from(v) })
                .collect(),
            (TypeChar::Uint, 8) => read_all::<u64, _>(key, npy)?
                .into_iter()
                .map(|v| {
                    if v == u64::from(u32::MAX) || v == u64::MAX {
                        -1
                    } else {
                        i64::try_from(v).unwrap_or(i64::MAX)
                    }
                })
                .collect(),
            _ => return Err(bad_dtype(key, descr)),
        };
        Ok((shape.clone(), to_c_order(data, &shape, order)))
    }

    fn open_entry(&mut self, key: &str) -> Result<npyz::NpyFile<impl Read + '_>> {
        match self.archive.by_name(key) {
            Ok(Some(npy)) => Ok(npy),
            Ok(None) => Err(SmplDeformError::MissingKey { key: key.into() }),
            Err(e) => Err(SmplDeformError::BadArray {
                key: key.into(),
                message: e.to_string(),
            }),
        }
    }

    fn header(
        &mut self,
        key: &str,
        shape_ok: &impl Fn(&[u64]) -> bool,
        expected: &str,
    ) -> Result<(Vec<u64>, Order, TypeChar, usize, String)> {
        let npy = self.open_entry(key)?;
        let shape = npy.shape().to_vec();
        let order = npy.order();
        let dtype = npy.dtype();
        let total = shape
            .iter()
            .try_fold(1u64, |acc, &d| acc.checked_mul(d))
            .unwrap_or(u64::MAX);
        if !shape_ok(&shape) || total > MAX_ELEMENTS {
            return Err(SmplDeformError::WrongShape {
                key: key.into(),
                found: shape,
                expected: expected.into(),
            });
        }
        match dtype {
            DType::Plain(ts) => {
                let bytes = ts.num_bytes().unwrap_or(0);
                Ok((shape, order, ts.type_char(), bytes, ts.to_string()))
            }
            other => Err(SmplDeformError::UnsupportedDtype {
                key: key.into(),
                dtype: other.descr(),
            }),
        }
    }
}

fn bad_dtype(key: &str, dtype: String) -> SmplDeformError {
    SmplDeformError::UnsupportedDtype {
        key: key.into(),
        dtype,
    }
}

fn read_all<T: npyz::Deserialize, R: Read>(key: &str, npy: npyz::NpyFile<R>) -> Result<Vec<T>> {
    npy.into_vec::<T>().map_err(|e| SmplDeformError::BadArray {
        key: key.into(),
        message: e.to_string(),
    })
}

/// Reorders Fortran-ordered data into C order (no-op for C order).
fn to_c_order<T: Copy>(data: Vec<T>, shape: &[u64], order: Order) -> Vec<T> {
    if matches!(order, Order::C) || shape.len() < 2 {
        return data;
    }
    let dims: Vec<usize> = shape.iter().map(|&d| d as usize).collect();
    let mut out = data.clone();
    let mut idx = vec![0usize; dims.len()];
    for (f_flat, &v) in data.iter().enumerate() {
        // Fortran flat index -> multi-index (first axis fastest).
        let mut rem = f_flat;
        for (k, &d) in dims.iter().enumerate() {
            idx[k] = rem % d;
            rem /= d;
        }
        let mut c_flat = 0usize;
        for (k, &d) in dims.iter().enumerate() {
            c_flat = c_flat * d + idx[k];
        }
        out[c_flat] = v;
    }
    out
}

/// Writes arrays into an `.npz` with fixed timestamps, stored (uncompressed) or deflated.
pub struct NpzWriter<W: Write + Seek> {
    zip: npyz::zip::ZipWriter<W>,
    compress: bool,
}

impl<W: Write + Seek> NpzWriter<W> {
    /// Starts an archive on `writer`; `compress` selects deflate over store.
    pub fn new(writer: W, compress: bool) -> Self {
        Self {
            zip: npyz::zip::ZipWriter::new(writer),
            compress,
        }
    }

    fn options(&self) -> npyz::zip::write::FileOptions {
        let method = if self.compress {
            npyz::zip::CompressionMethod::Deflated
        } else {
            npyz::zip::CompressionMethod::Stored
        };
        npyz::zip::write::FileOptions::default()
            .compression_method(method)
            .last_modified_time(npyz::zip::DateTime::default())
            .unix_permissions(0o644)
    }

    /// Adds a little-endian f32 array of the given shape (C order).
    pub fn add_f32(&mut self, key: &str, shape: &[u64], data: &[f32]) -> std::io::Result<()> {
        self.add(key, shape, data)
    }

    /// Adds a little-endian i64 array of the given shape (C order).
    pub fn add_i64(&mut self, key: &str, shape: &[u64], data: &[i64]) -> std::io::Result<()> {
        self.add(key, shape, data)
    }

    /// Adds a little-endian u32 array of the given shape (C order).
    pub fn add_u32(&mut self, key: &str, shape: &[u64], data: &[u32]) -> std::io::Result<()> {
        self.add(key, shape, data)
    }

    /// Adds a little-endian f64 array of the given shape (C order).
    pub fn add_f64(&mut self, key: &str, shape: &[u64], data: &[f64]) -> std::io::Result<()> {
        self.add(key, shape, data)
    }

    fn add<T: npyz::AutoSerialize + Copy>(
        &mut self,
        key: &str,
        shape: &[u64],
        data: &[T],
    ) -> std::io::Result<()> {
        let mut buf = Vec::new();
        {
            let mut w = npyz::WriteOptions::new()
                .default_dtype()
                .shape(shape)
                .writer(&mut buf)
                .begin_nd()?;
            w.extend(data.iter().copied())?;
            w.finish()?;
        }
        let options = self.options();
        self.zip
            .start_file(format!("{key}.npy"), options)
            .map_err(std::io::Error::other)?;
        self.zip.write_all(&buf)
    }

    /// Finishes the archive and returns the writer.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.zip.finish().map_err(std::io::Error::other)
    }
}
