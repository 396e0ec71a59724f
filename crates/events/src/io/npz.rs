//! `.npz` events: a zip of `x.npy`, `y.npy`, `t.npy`, `p.npy` (numpy `savez`, stored or deflated).
//!
//! Reading streams each column from its own file handle when the entry is stored (numpy's default
//! `savez`); a deflated entry (`savez_compressed`) is decompressed into memory as it is read, never
//! pre-sized by its header. Accepted dtypes: any little- or big-endian integer or float, or bool.
//! `t` is microseconds when integer and seconds when float; `p` > 0 is +1, otherwise -1; `x`, `y`
//! must fit u16. Written files hold `t` as `<i8` (µs), `x`, `y` as `<u2`, `p` as `|i1` (±1),
//! uncompressed, so write → read is lossless.

use std::fs::File;
use std::io::{BufReader, BufWriter, Cursor, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::EventReader;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

/// Element type of one npy column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Int,
    Uint,
    Float,
    Bool,
}

/// One column of an npz archive, positioned at its raw data.
struct Column {
    name: &'static str,
    reader: Box<dyn Read + Send>,
    kind: Kind,
    size: usize,
    big_endian: bool,
    len: u64,
    buf: Vec<u8>,
}

impl Column {
    fn open(path: &Path, name: &'static str) -> Result<Self> {
        let fmt = |m: String| EventsError::format(path, format!("array {name}: {m}"));
        let file = File::open(path).map_err(|e| EventsError::io(path, e))?;
        let mut zip =
            zip::ZipArchive::new(BufReader::new(file)).map_err(|e| fmt(format!("zip: {e}")))?;
        let entry_name = format!("{name}.npy");
        let mut entry = zip
            .by_name(&entry_name)
            .map_err(|e| fmt(format!("missing {entry_name}: {e}")))?;
        let mut reader: Box<dyn Read + Send> =
            if entry.compression() == zip::CompressionMethod::Stored {
                let (start, size) = (entry.data_start(), entry.size());
                drop(entry);
                let mut f = File::open(path).map_err(|e| EventsError::io(path, e))?;
                f.seek(SeekFrom::Start(start))
                    .map_err(|e| EventsError::io(path, e))?;
                Box::new(BufReader::with_capacity(1 << 18, f.take(size)))
            } else {
                let mut v = Vec::new();
                entry
                    .read_to_end(&mut v)
                    .map_err(|e| fmt(format!("decompressing: {e}")))?;
                Box::new(Cursor::new(v))
            };
        let header = npyz::NpyHeader::from_reader(&mut reader)
            .map_err(|e| fmt(format!("npy header: {e}")))?;
        if header.shape().len() != 1 {
            return Err(fmt(format!(
                "shape {:?} is not 1-dimensional",
                header.shape()
            )));
        }
        let npyz::DType::Plain(ts) = header.dtype() else {
            return Err(fmt(format!(
                "dtype {} is not a plain number",
                header.dtype().descr()
            )));
        };
        let size = ts.num_bytes().unwrap_or(0);
        let kind = match ts.type_char() {
            npyz::TypeChar::Int => Kind::Int,
            npyz::TypeChar::Uint => Kind::Uint,
            npyz::TypeChar::Float => Kind::Float,
            npyz::TypeChar::Bool => Kind::Bool,
            _ => return Err(fmt(format!("dtype {ts} is not a number"))),
        };
        let ok_size = match kind {
            Kind::Float => size == 4 || size == 8,
            Kind::Bool => size == 1,
            _ => matches!(size, 1 | 2 | 4 | 8),
        };
        if !ok_size {
            return Err(fmt(format!("dtype {ts} has an unsupported size")));
        }
        Ok(Self {
            name,
            reader,
            kind,
            size,
            big_endian: ts.endianness() == npyz::Endianness::Big,
            len: header.shape()[0],
            buf: Vec::new(),
        })
    }

    /// Reads the next `n` raw elements into `self.buf`.
    fn fill(&mut self, n: usize, path: &Path) -> Result<()> {
        self.buf.resize(n * self.size, 0);
        self.reader.read_exact(&mut self.buf).map_err(|e| {
            EventsError::format(path, format!("array {}: truncated data ({e})", self.name))
        })
    }

    /// Element `i` of the buffer as (integer value, float value) — one of them is meaningful.
    #[inline]
    fn int_at(&self, i: usize) -> i128 {
        let b = &self.buf[i * self.size..(i + 1) * self.size];
        let mut a = [0u8; 8];
        if self.big_endian {
            for k in 0..self.size {
                a[k] = b[self.size - 1 - k];
            }
        } else {
            a[..self.size].copy_from_slice(b);
        }
        let u = u64::from_le_bytes(a);
        match self.kind {
            Kind::Int => {
                let shift = 64 - 8 * self.size as u32;
                (((u << shift) as i64) >> shift) as i128
            }
            _ => u as i128,
        }
    }

    #[inline]
    fn float_at(&self, i: usize) -> f64 {
        let b = &self.buf[i * self.size..(i + 1) * self.size];
        match (self.size, self.big_endian) {
            (4, false) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            (4, true) => f32::from_be_bytes([b[0], b[1], b[2], b[3]]) as f64,
            (_, false) => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
            (_, true) => f64::from_be_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }

    fn value_f64(&self, i: usize) -> f64 {
        if self.kind == Kind::Float {
            self.float_at(i)
        } else {
            self.int_at(i) as f64
        }
    }
}

/// Streaming `.npz` event reader.
pub struct NpzReader {
    path: PathBuf,
    cols: [Column; 4],
    remaining: u64,
    done: u64,
    total: Option<u64>,
}

impl NpzReader {
    /// Opens an `.npz` with arrays `t`, `x`, `y`, `p` of equal length.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let total = std::fs::metadata(path).ok().map(|m| m.len());
        let cols = [
            Column::open(path, "t")?,
            Column::open(path, "x")?,
            Column::open(path, "y")?,
            Column::open(path, "p")?,
        ];
        let n = cols[0].len;
        if let Some(c) = cols.iter().find(|c| c.len != n) {
            return Err(EventsError::format(
                path,
                format!("array {} has {} elements but t has {n}", c.name, c.len),
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            cols,
            remaining: n,
            done: 0,
            total,
        })
    }

    /// Number of events the arrays declare (checked against the data only as it is read).
    pub fn declared_len(&self) -> u64 {
        self.remaining + self.done
    }
}

impl EventReader for NpzReader {
    fn format(&self) -> &'static str {
        "npz"
    }

    fn sensor(&self) -> Option<SensorSize> {
        None
    }

    fn read_chunk(&mut self, out: &mut EventStream, max: usize) -> Result<usize> {
        let n = (self.remaining.min(max as u64).min(1 << 20)) as usize;
        if n == 0 {
            return Ok(0);
        }
        for c in self.cols.iter_mut() {
            c.fill(n, &self.path)?;
        }
        let [ct, cx, cy, cp] = &self.cols;
        let base = self.done;
        let bad = |name: &str, i: usize, v: String| {
            EventsError::format(
                &self.path,
                format!("array {name}[{}] = {v} is out of range", base + i as u64),
            )
        };
        out.t.reserve(n);
        if ct.kind == Kind::Float {
            for i in 0..n {
                let us = (ct.float_at(i) * 1e6).round();
                if !(us.is_finite() && us.abs() < 9.0e18) {
                    return Err(bad("t", i, ct.float_at(i).to_string()));
                }
                out.t.push(us as i64);
            }
        } else if ct.size == 8 && ct.kind == Kind::Int && !ct.big_endian {
            out.t.extend(
                ct.buf
                    .chunks_exact(8)
                    .map(|b| i64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])),
            );
        } else {
            for i in 0..n {
                let v = ct.int_at(i);
                out.t
                    .push(i64::try_from(v).map_err(|_| bad("t", i, v.to_string()))?);
            }
        }
        for (c, dst, name) in [(cx, &mut out.x, "x"), (cy, &mut out.y, "y")] {
            dst.reserve(n);
            if c.size == 2 && c.kind == Kind::Uint && !c.big_endian {
                dst.extend(
                    c.buf
                        .chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]])),
                );
            } else {
                for i in 0..n {
                    let v = c.value_f64(i);
                    if !((0.0..=65535.0).contains(&v) && v.fract() == 0.0) {
                        return Err(bad(name, i, v.to_string()));
                    }
                    dst.push(v as u16);
                }
            }
        }
        out.p.reserve(n);
        if cp.size == 1 && cp.kind != Kind::Float {
            let signed = cp.kind == Kind::Int;
            out.p.extend(cp.buf.iter().map(|&b| {
                let v = if signed { b as i8 as i16 } else { b as i16 };
                if v > 0 {
                    1i8
                } else {
                    -1
                }
            }));
        } else {
            for i in 0..n {
                out.p.push(if cp.value_f64(i) > 0.0 { 1 } else { -1 });
            }
        }
        self.remaining -= n as u64;
        self.done += n as u64;
        Ok(n)
    }

    fn bytes_read(&self) -> u64 {
        let per: u64 = self.cols.iter().map(|c| c.size as u64).sum();
        self.done * per
    }

    fn total_bytes(&self) -> Option<u64> {
        self.total
    }
}

/// The npy v1.0 header for a 1-D little-endian array of `n` elements of dtype `descr`.
fn npy_header(descr: &str, n: usize) -> Vec<u8> {
    let dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({n},), }}");
    let unpadded = 10 + dict.len() + 1;
    let pad = (64 - unpadded % 64) % 64;
    let mut h = Vec::with_capacity(unpadded + pad);
    h.extend_from_slice(b"\x93NUMPY\x01\x00");
    h.extend_from_slice(&((dict.len() + pad + 1) as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h.extend(std::iter::repeat_n(b' ', pad));
    h.push(b'\n');
    h
}

/// Writes events as an uncompressed `.npz` (`t` `<i8` µs, `x`/`y` `<u2`, `p` `|i1` ±1).
pub fn write_npz(path: impl AsRef<Path>, events: &EventStream) -> Result<()> {
    let path = path.as_ref();
    let io = |e: std::io::Error| EventsError::io(path, e);
    let zerr = |e: zip::result::ZipError| EventsError::format(path, format!("zip write: {e}"));
    let f = File::create(path).map_err(io)?;
    let mut zw = zip::ZipWriter::new(BufWriter::with_capacity(1 << 20, f));
    let n = events.len();
    let opts = |bytes: usize| {
        zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .large_file(bytes as u64 + 128 >= u32::MAX as u64)
    };
    let mut chunk = Vec::with_capacity(1 << 20);
    zw.start_file("t.npy", opts(8 * n)).map_err(zerr)?;
    zw.write_all(&npy_header("<i8", n)).map_err(io)?;
    for c in events.t.chunks(1 << 16) {
        chunk.clear();
        c.iter()
            .for_each(|v| chunk.extend_from_slice(&v.to_le_bytes()));
        zw.write_all(&chunk).map_err(io)?;
    }
    for (name, col) in [("x.npy", &events.x), ("y.npy", &events.y)] {
        zw.start_file(name, opts(2 * n)).map_err(zerr)?;
        zw.write_all(&npy_header("<u2", n)).map_err(io)?;
        for c in col.chunks(1 << 16) {
            chunk.clear();
            c.iter()
                .for_each(|v| chunk.extend_from_slice(&v.to_le_bytes()));
            zw.write_all(&chunk).map_err(io)?;
        }
    }
    zw.start_file("p.npy", opts(n)).map_err(zerr)?;
    zw.write_all(&npy_header("|i1", n)).map_err(io)?;
    for c in events.p.chunks(1 << 16) {
        chunk.clear();
        chunk.extend(c.iter().map(|&v| v as u8));
        zw.write_all(&chunk).map_err(io)?;
    }
    let mut w = zw.finish().map_err(zerr)?;
    w.flush().map_err(io)
}
