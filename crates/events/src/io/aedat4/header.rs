//! The AEDAT 4 header: the magic, the FlatBuffers `IOHE` table (compression, data-table position,
//! XML description) read with a bounds check on every offset, and the description's stream scan.

use std::io::Read;
use std::path::Path;

use crate::error::{EventsError, Result};
use crate::stream::SensorSize;

/// File magic.
pub const MAGIC: &[u8; 14] = b"#!AER-DAT4.0\r\n";
/// Largest header accepted (bytes).
const MAX_HEADER: u64 = 16 << 20;

/// Packet compression of an AEDAT 4 file (the IOHeader `CompressionType`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Uncompressed.
    None,
    /// LZ4 frame.
    Lz4,
    /// LZ4 frame, high compression.
    Lz4High,
    /// Zstandard frame.
    Zstd,
    /// Zstandard frame, high compression.
    ZstdHigh,
}

impl Compression {
    /// The name DV writes in a stream's description (`NONE`, `LZ4`, `LZ4_HIGH`, `ZSTD`,
    /// `ZSTD_HIGH`).
    pub fn name(self) -> &'static str {
        match self {
            Compression::None => "NONE",
            Compression::Lz4 => "LZ4",
            Compression::Lz4High => "LZ4_HIGH",
            Compression::Zstd => "ZSTD",
            Compression::ZstdHigh => "ZSTD_HIGH",
        }
    }

    fn from_i32(v: i32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::Lz4,
            2 => Self::Lz4High,
            3 => Self::Zstd,
            4 => Self::ZstdHigh,
            _ => return None,
        })
    }
}

/// Bounds-checked little-endian reads in a FlatBuffers byte slice.
pub(in crate::io) struct Fb<'a>(pub(in crate::io) &'a [u8]);

impl<'a> Fb<'a> {
    pub(in crate::io) fn bytes(&self, at: usize, n: usize) -> Option<&'a [u8]> {
        self.0.get(at..at.checked_add(n)?)
    }
    pub(in crate::io) fn u16(&self, at: usize) -> Option<u16> {
        let b = self.bytes(at, 2)?;
        Some(u16::from_le_bytes([b[0], b[1]]))
    }
    pub(in crate::io) fn u32(&self, at: usize) -> Option<u32> {
        let b = self.bytes(at, 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    pub(in crate::io) fn i64(&self, at: usize) -> Option<i64> {
        let b = self.bytes(at, 8)?;
        Some(i64::from_le_bytes([
            b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7],
        ]))
    }
    /// Follows a uoffset stored at `at`.
    pub(in crate::io) fn deref(&self, at: usize) -> Option<usize> {
        at.checked_add(self.u32(at)? as usize)
    }
    /// Absolute position of field `i` of the table at `table`, or None when absent.
    pub(in crate::io) fn field(&self, table: usize, i: usize) -> Option<Option<usize>> {
        let soff = self.u32(table)? as i32 as i64;
        let vt = usize::try_from(table as i64 - soff).ok()?;
        let vt_size = self.u16(vt)? as usize;
        let slot = 4 + 2 * i;
        if slot + 2 > vt_size {
            return Some(None);
        }
        let off = self.u16(vt + slot)? as usize;
        Some(if off == 0 { None } else { Some(table + off) })
    }
}

/// What the IOHeader says.
pub(in crate::io) struct Header {
    pub(in crate::io) compression: Compression,
    pub(in crate::io) data_table_position: i64,
    pub(in crate::io) description: String,
}

/// Reads and checks the magic, the header length and the IOHeader of an AEDAT 4 file of
/// `file_len` bytes; returns the header and the file position after it.
pub(in crate::io) fn read_header<R: Read>(
    reader: &mut R,
    file_len: u64,
    path: &Path,
) -> Result<(Header, u64)> {
    let mut magic = [0u8; 14];
    reader
        .read_exact(&mut magic)
        .map_err(|_| EventsError::format(path, "truncated before the AEDAT 4 magic"))?;
    if &magic != MAGIC {
        return Err(EventsError::format(
            path,
            format!("magic {magic:?} is not #!AER-DAT4.0"),
        ));
    }
    let mut lb = [0u8; 4];
    reader
        .read_exact(&mut lb)
        .map_err(|_| EventsError::format(path, "truncated header length"))?;
    let hlen = u32::from_le_bytes(lb) as u64;
    if hlen > MAX_HEADER || 18 + hlen > file_len {
        return Err(EventsError::format(
            path,
            format!("header length {hlen} exceeds the file ({file_len} bytes) or {MAX_HEADER}"),
        ));
    }
    let mut hbuf = vec![0u8; hlen as usize];
    reader
        .read_exact(&mut hbuf)
        .map_err(|_| EventsError::format(path, "truncated header"))?;
    Ok((parse_ioheader(&hbuf, path)?, 18 + hlen))
}

fn parse_ioheader(buf: &[u8], path: &Path) -> Result<Header> {
    let bad = |m: &str| EventsError::format(path, format!("IOHeader: {m}"));
    let fb = Fb(buf);
    if fb.bytes(4, 4) != Some(b"IOHE") {
        return Err(bad("file identifier is not IOHE"));
    }
    let table = fb
        .deref(0)
        .ok_or_else(|| bad("root offset out of bounds"))?;
    let f = |i| {
        fb.field(table, i)
            .ok_or_else(|| bad("table or vtable out of bounds"))
    };
    let compression = match f(0)? {
        Some(p) => {
            let v = fb.u32(p).ok_or_else(|| bad("compression out of bounds"))? as i32;
            Compression::from_i32(v).ok_or_else(|| bad(&format!("unknown compression {v}")))?
        }
        None => Compression::None,
    };
    let data_table_position = match f(1)? {
        Some(p) => fb
            .i64(p)
            .ok_or_else(|| bad("dataTablePosition out of bounds"))?,
        None => -1,
    };
    let description = match f(2)? {
        Some(p) => {
            let s = fb
                .deref(p)
                .ok_or_else(|| bad("infoNode offset out of bounds"))?;
            let n = fb
                .u32(s)
                .ok_or_else(|| bad("infoNode length out of bounds"))? as usize;
            let b = fb
                .bytes(s + 4, n)
                .ok_or_else(|| bad(&format!("infoNode length {n} out of bounds")))?;
            String::from_utf8_lossy(b).into_owned()
        }
        None => String::new(),
    };
    Ok(Header {
        compression,
        data_table_position,
        description,
    })
}

/// Text of the first `<attr key="KEY" ...>TEXT</attr>` in `s`.
fn attr<'s>(s: &'s str, key: &str) -> Option<&'s str> {
    let i = s.find(&format!("key=\"{key}\""))?;
    let rest = &s[i..];
    let start = rest.find('>')? + 1;
    let end = rest[start..].find('<')? + start;
    Some(rest[start..end].trim())
}

/// Finds the first stream of type `type_id` (`EVTS`, `FRME`, …) in the XML description: (stream
/// id, sensor size if stated). A tolerant scan, not a full XML parser: the DV description is
/// machine-written.
pub(in crate::io) fn find_stream(desc: &str, type_id: &str) -> Option<(u32, Option<SensorSize>)> {
    let out = desc.find("name=\"outInfo\"")?;
    let body = &desc[out..];
    let mut search = 0;
    while let Some(i) = body[search..].find("<node name=\"") {
        let start = search + i + "<node name=\"".len();
        let end = body[start..].find('"')? + start;
        search = end;
        let Ok(id) = body[start..end].parse::<u32>() else {
            continue;
        };
        // The stream node ends at its next sibling, which follows its nested "info" node.
        let next_stream = body[end..]
            .match_indices("<node name=\"")
            .map(|(k, _)| k + end)
            .find(|&k| {
                let s = k + "<node name=\"".len();
                body[s..]
                    .split('"')
                    .next()
                    .is_some_and(|n| n.parse::<u32>().is_ok())
            })
            .unwrap_or(body.len());
        let node = &body[end..next_stream];
        if attr(node, "typeIdentifier") == Some(type_id) {
            let w = attr(node, "sizeX").and_then(|v| v.parse::<u32>().ok());
            let h = attr(node, "sizeY").and_then(|v| v.parse::<u32>().ok());
            let size = match (w, h) {
                (Some(w), Some(h)) if w > 0 && h > 0 => Some(SensorSize::new(w, h)),
                _ => None,
            };
            return Some((id, size));
        }
    }
    None
}
