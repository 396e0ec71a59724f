//! AEDAT 4 (iniVation DV) event files: `#!AER-DAT4.0\r\n`, a u32 length and a FlatBuffers `IOHE`
//! header (compression None/LZ4/LZ4High/Zstd/ZstdHigh, data-table position, XML description with
//! the streams and the sensor size), then packets `[u32 stream id][u32 size][payload]` up to the data
//! table. A payload is (after decompression: LZ4 frame or zstd frame) a size-prefixed FlatBuffers
//! `EVTS` `EventPacket { elements: [Event { t: i64 µs, x: i16, y: i16, on: bool }] }` (16-byte structs).
//!
//! Tables are decoded by hand with a bounds check on every offset: no `flatc` at build time, no
//! `unsafe`, no allocation sized by a header value that was not first checked against the file size.
//! Only the first `EVTS` stream of the description is read; other streams are skipped.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use super::EventReader;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};
use rayon::prelude::*;

/// File magic.
pub const MAGIC: &[u8; 14] = b"#!AER-DAT4.0\r\n";
/// Largest header accepted (bytes).
const MAX_HEADER: u64 = 16 << 20;
/// Largest packet accepted, compressed or not (bytes).
pub(super) const MAX_PACKET: u64 = 512 << 20;
/// Packets read ahead and decompressed in parallel at a time.
const READ_AHEAD: usize = 16;
/// Compressed bytes read ahead at most (besides the one packet that crosses it).
const READ_AHEAD_BYTES: usize = 16 << 20;
/// Batches decompressing on the rayon pool at once: two, so that the pool always has a queued
/// batch while the reading thread reads the next one from the file and decodes the current one.
const BATCHES_IN_FLIGHT: usize = 2;

/// Largest decompressed/compressed size ratio for which a zstd frame's stated content size is used
/// to size the output buffer up front (event packets compress 3–10×); larger claims are decoded by
/// streaming, which allocates only as data arrives.
const ONE_SHOT_MAX_RATIO: u64 = 64;

thread_local! {
    /// The zstd decompression context of this thread (see `Aedat4Reader::fill_ahead`).
    static ZSTD_CONTEXT: std::cell::RefCell<Option<zstd::zstd_safe::DCtx<'static>>> =
        const { std::cell::RefCell::new(None) };
}

/// A packet read ahead: its decompressed payload, its compressed payload if it needs more than the
/// read-ahead cap, or the decompression error.
enum Ahead {
    Decoded(Vec<u8>),
    TooLarge(Vec<u8>),
    Failed(String),
}

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
pub(super) struct Fb<'a>(pub(super) &'a [u8]);

impl<'a> Fb<'a> {
    pub(super) fn bytes(&self, at: usize, n: usize) -> Option<&'a [u8]> {
        self.0.get(at..at.checked_add(n)?)
    }
    pub(super) fn u16(&self, at: usize) -> Option<u16> {
        let b = self.bytes(at, 2)?;
        Some(u16::from_le_bytes([b[0], b[1]]))
    }
    pub(super) fn u32(&self, at: usize) -> Option<u32> {
        let b = self.bytes(at, 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    pub(super) fn i64(&self, at: usize) -> Option<i64> {
        let b = self.bytes(at, 8)?;
        Some(i64::from_le_bytes([
            b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7],
        ]))
    }
    /// Follows a uoffset stored at `at`.
    pub(super) fn deref(&self, at: usize) -> Option<usize> {
        at.checked_add(self.u32(at)? as usize)
    }
    /// Absolute position of field `i` of the table at `table`, or None when absent.
    pub(super) fn field(&self, table: usize, i: usize) -> Option<Option<usize>> {
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
pub(super) struct Header {
    pub(super) compression: Compression,
    pub(super) data_table_position: i64,
    pub(super) description: String,
}

/// Reads and checks the magic, the header length and the IOHeader of an AEDAT 4 file of
/// `file_len` bytes; returns the header and the file position after it.
pub(super) fn read_header<R: Read>(
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
pub(super) fn find_stream(desc: &str, type_id: &str) -> Option<(u32, Option<SensorSize>)> {
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

/// Streaming AEDAT 4 reader (events of the first EVTS stream).
pub struct Aedat4Reader<R: Read> {
    reader: R,
    path: PathBuf,
    compression: Compression,
    data_table_position: i64,
    stream_id: u32,
    sensor: Option<SensorSize>,
    position: u64,
    file_len: u64,
    raw: Vec<u8>,
    packet: Vec<u8>,
    /// zstd decompression context, created at the first zstd packet and reused for every packet
    /// (a fresh context per packet re-allocates its window and dominated the decoding time).
    zstd: Option<zstd::zstd_safe::DCtx<'static>>,
    /// Packets of our stream read ahead and decompressed in parallel, in file order.
    ahead: std::collections::VecDeque<Ahead>,
    /// File bytes (header included) of each packet in `ahead` and in flight, in file order, and
    /// their sum: read from the file but not yet handed out, so not counted by `bytes_read`.
    unconsumed: std::collections::VecDeque<u64>,
    unconsumed_bytes: u64,
    /// An error met while reading ahead, raised once the packets before it are consumed.
    deferred: Option<EventsError>,
    /// The next batches of packets, in file order, decompressing on the rayon pool while this
    /// one is decoded (at most [`BATCHES_IN_FLIGHT`]).
    in_flight: std::collections::VecDeque<std::sync::mpsc::Receiver<Vec<Ahead>>>,
    cursor: usize,
    count: usize,
    done: bool,
    /// The last event's time handed out (µs; `i64::MIN` before the first).
    last_t: i64,
}

impl Aedat4Reader<BufReader<File>> {
    /// Opens an AEDAT 4 file and parses its header.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
        let len = f.metadata().map_err(|e| EventsError::io(path, e))?.len();
        Self::new(BufReader::with_capacity(1 << 20, f), len, path)
    }
}

impl<R: Read> Aedat4Reader<R> {
    /// A reader over `reader` holding `file_len` bytes (`path` names it in errors).
    pub fn new(mut reader: R, file_len: u64, path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let (h, position) = read_header(&mut reader, file_len, &path)?;
        let (stream_id, sensor) = find_stream(&h.description, "EVTS").ok_or_else(|| {
            EventsError::format(
                &path,
                "description has no EVTS stream in outInfo".to_string(),
            )
        })?;
        Ok(Self {
            reader,
            path,
            compression: h.compression,
            data_table_position: h.data_table_position,
            stream_id,
            sensor,
            position,
            file_len,
            raw: Vec::new(),
            packet: Vec::new(),
            zstd: None,
            ahead: std::collections::VecDeque::new(),
            deferred: None,
            in_flight: std::collections::VecDeque::new(),
            unconsumed: std::collections::VecDeque::new(),
            unconsumed_bytes: 0,
            cursor: 0,
            count: 0,
            done: false,
            last_t: i64::MIN,
        })
    }

    /// Reads the next packet of our stream's compressed payload into `self.raw`; false at the end
    /// of the packets.
    fn next_raw(&mut self) -> Result<bool> {
        loop {
            if self.data_table_position >= 0 && self.position >= self.data_table_position as u64 {
                return Ok(false);
            }
            let mut hdr = [0u8; 8];
            match super::read_full(&mut self.reader, &mut hdr) {
                Ok(0) => return Ok(false),
                Ok(8) => {}
                Ok(n) => {
                    return Err(EventsError::format(
                        &self.path,
                        format!(
                            "truncated packet header at byte {} ({n} of 8 bytes)",
                            self.position
                        ),
                    ))
                }
                Err(e) => return Err(EventsError::io(&self.path, e)),
            }
            let id = u32::from_le_bytes([hdr[0], hdr[1], hdr[2], hdr[3]]);
            let size = u32::from_le_bytes([hdr[4], hdr[5], hdr[6], hdr[7]]) as u64;
            let remaining = self.file_len.saturating_sub(self.position + 8);
            if size > remaining || size > MAX_PACKET {
                return Err(EventsError::format(
                    &self.path,
                    format!(
                        "packet at byte {} claims {size} bytes, only {remaining} remain",
                        self.position
                    ),
                ));
            }
            self.raw.resize(size as usize, 0);
            self.reader.read_exact(&mut self.raw).map_err(|_| {
                EventsError::format(
                    &self.path,
                    format!("truncated packet at byte {}", self.position),
                )
            })?;
            self.position += 8 + size;
            if id == self.stream_id {
                return Ok(true);
            }
        }
    }

    /// Reads up to [`READ_AHEAD`] compressed packets of our stream (at most [`READ_AHEAD_BYTES`]
    /// besides the one that crosses it). A read error is kept in `deferred`, to be raised once the
    /// packets before it are consumed.
    fn read_batch(&mut self) -> Vec<Vec<u8>> {
        let mut raws = Vec::new();
        let mut compressed = 0usize;
        while raws.len() < READ_AHEAD && compressed < READ_AHEAD_BYTES {
            match self.next_raw() {
                Ok(true) => {
                    compressed += self.raw.len();
                    let bytes = 8 + self.raw.len() as u64;
                    self.unconsumed.push_back(bytes);
                    self.unconsumed_bytes += bytes;
                    raws.push(std::mem::take(&mut self.raw));
                }
                Ok(false) => break,
                Err(e) => {
                    self.deferred = Some(e);
                    break;
                }
            }
        }
        raws
    }

    /// Reads the next batch and starts decompressing it on the rayon pool, so that it runs while
    /// the caller decodes the batch before it; false if there was nothing (more) to read. Inside
    /// the pool (where blocking on the result could starve it) or without compression, the batch
    /// is decompressed here instead.
    fn start_next_batch(&mut self) -> bool {
        let raws = self.read_batch();
        if raws.is_empty() {
            return false;
        }
        let compression = self.compression;
        if compression == Compression::None || rayon::current_thread_index().is_some() {
            self.ahead.extend(decompress_batch(compression, raws));
            return false;
        }
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        rayon::spawn(move || {
            // The reader may have been dropped meanwhile; then nobody wants the packets.
            let _ = tx.send(decompress_batch(compression, raws));
        });
        self.in_flight.push_back(rx);
        true
    }

    /// Refills `ahead` with the next batch of decompressed packets, in file order: the batch that
    /// was decompressing in the background if any, else one read and decompressed now; then starts
    /// the batches after it, up to [`BATCHES_IN_FLIGHT`]. False if no packet was left (a pending
    /// read error is returned instead).
    fn fill_ahead(&mut self) -> Result<bool> {
        if let Some(rx) = self.in_flight.pop_front() {
            let batch = rx.recv().map_err(|_| {
                EventsError::format(&self.path, "the packet decompression task stopped")
            })?;
            self.ahead.extend(batch);
        } else {
            let raws = self.read_batch();
            if raws.is_empty() {
                return match self.deferred.take() {
                    Some(e) => Err(e),
                    None => Ok(false),
                };
            }
            self.ahead.extend(decompress_batch(self.compression, raws));
        }
        while self.deferred.is_none()
            && self.in_flight.len() < BATCHES_IN_FLIGHT
            && self.start_next_batch()
        {}
        Ok(true)
    }

    /// Loads the next EVTS packet of our stream; false at the end of the packets.
    fn next_packet(&mut self) -> Result<bool> {
        loop {
            if self.ahead.is_empty() {
                // A read error comes after every packet read before it (some may be in flight).
                if self.in_flight.is_empty() {
                    if let Some(e) = self.deferred.take() {
                        return Err(e);
                    }
                }
                if !self.fill_ahead()? {
                    return Ok(false);
                }
            }
            let Some(next) = self.ahead.pop_front() else {
                return Ok(false);
            };
            if let Some(bytes) = self.unconsumed.pop_front() {
                self.unconsumed_bytes -= bytes;
            }
            match next {
                Ahead::Decoded(p) => self.packet = p,
                Ahead::Failed(e) => {
                    return Err(EventsError::format(
                        &self.path,
                        format!("decompressing packet: {e}"),
                    ))
                }
                Ahead::TooLarge(raw) => {
                    if self.zstd.is_none() {
                        self.zstd = zstd::zstd_safe::DCtx::try_create();
                    }
                    let mut out = std::mem::take(&mut self.packet);
                    decompress(
                        self.compression,
                        &raw,
                        self.zstd.as_mut(),
                        MAX_PACKET,
                        &mut out,
                    )
                    .map_err(|e| {
                        EventsError::format(&self.path, format!("decompressing packet: {e}"))
                    })?;
                    self.packet = out;
                }
            }
            let fb = Fb(&self.packet);
            let bad = |m: String| EventsError::format(&self.path, format!("EventPacket: {m}"));
            if fb.bytes(8, 4) != Some(b"EVTS") {
                return Err(bad("identifier is not EVTS".to_string()));
            }
            let table = fb
                .deref(4)
                .ok_or_else(|| bad("root offset out of bounds".to_string()))?;
            // Size-prefixed: offsets are relative to the buffer after the 4-byte prefix.
            let body = Fb(&self.packet[4..]);
            let table = table - 4;
            let Some(field) = body
                .field(table, 0)
                .ok_or_else(|| bad("table out of bounds".to_string()))?
            else {
                continue; // no elements
            };
            let vec = body
                .deref(field)
                .ok_or_else(|| bad("elements offset out of bounds".to_string()))?;
            let n = body
                .u32(vec)
                .ok_or_else(|| bad("elements length out of bounds".to_string()))?
                as usize;
            let need = (n as u64) * 16;
            if (vec as u64 + 4 + need) > body.0.len() as u64 {
                return Err(bad(format!(
                    "{n} elements exceed the {}-byte packet",
                    body.0.len()
                )));
            }
            self.cursor = 4 + vec + 4;
            self.count = n;
            if n > 0 {
                return Ok(true);
            }
        }
    }
}

/// Decompresses `raw` into `out` with at most `cap` bytes of output (+1 to detect overflow).
pub(super) fn decompress(
    compression: Compression,
    raw: &[u8],
    ctx: Option<&mut zstd::zstd_safe::DCtx<'static>>,
    cap: u64,
    out: &mut Vec<u8>,
) -> std::io::Result<()> {
    out.clear();
    match compression {
        Compression::None => out.extend_from_slice(raw),
        Compression::Lz4 | Compression::Lz4High => {
            lz4_flex::frame::FrameDecoder::new(raw)
                .take(cap)
                .read_to_end(out)?;
        }
        Compression::Zstd | Compression::ZstdHigh => match ctx {
            // A single frame that states its size within the cap (what one-shot encoders such as
            // DV's write) is decoded in one call into an exactly sized buffer: no streaming
            // window copies, no buffer regrowth. Anything else (no stated size, several frames,
            // a size over the cap) goes through the streaming decoder, which enforces the cap.
            // Both reset the session first, so a failed packet leaves nothing behind.
            Some(ctx) => {
                let stated = zstd::zstd_safe::get_frame_content_size(raw).ok().flatten();
                let one_shot = match stated {
                    // The claim is trusted only within the cap and a plausible compression
                    // ratio, so a small packet cannot make us reserve a huge buffer.
                    Some(n) if n < cap && n <= ONE_SHOT_MAX_RATIO * raw.len() as u64 + 4096 => {
                        out.reserve_exact(n as usize);
                        ctx.decompress(out, raw).is_ok() && out.len() as u64 == n
                    }
                    _ => false,
                };
                if !one_shot {
                    out.clear();
                    zstd::stream::read::Decoder::with_context(raw, ctx)
                        .take(cap)
                        .read_to_end(out)?;
                }
            }
            None => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::OutOfMemory,
                    "cannot create a zstd decompression context",
                ))
            }
        },
    }
    Ok(())
}

/// Decompresses a batch of packets in parallel, in order (each with an output cap of
/// `MAX_PACKET / READ_AHEAD`; a packet that needs more is marked [`Ahead::TooLarge`] and
/// decompressed again alone, with the full cap, when its turn comes).
fn decompress_batch(compression: Compression, raws: Vec<Vec<u8>>) -> Vec<Ahead> {
    if compression == Compression::None {
        return raws.into_iter().map(Ahead::Decoded).collect();
    }
    let cap = MAX_PACKET / READ_AHEAD as u64;
    raws.into_par_iter()
        .map(|raw| {
            let mut out = Vec::new();
            // One zstd context per worker thread, kept across packets and batches (creating one
            // allocates its window, which costs more than decoding a packet).
            let res = ZSTD_CONTEXT.with(|cell| {
                let mut ctx = cell.borrow_mut();
                let zstd = matches!(compression, Compression::Zstd | Compression::ZstdHigh);
                if ctx.is_none() && zstd {
                    *ctx = zstd::zstd_safe::DCtx::try_create();
                }
                decompress(compression, &raw, ctx.as_mut(), cap + 1, &mut out)
            });
            match res {
                Ok(()) if (out.len() as u64) <= cap => Ahead::Decoded(out),
                Ok(()) => Ahead::TooLarge(raw),
                Err(e) => Ahead::Failed(e.to_string()),
            }
        })
        .collect()
}

impl<R: Read> EventReader for Aedat4Reader<R> {
    fn format(&self) -> &'static str {
        "aedat4"
    }

    fn sensor(&self) -> Option<SensorSize> {
        self.sensor
    }

    fn read_chunk(&mut self, out: &mut EventStream, max: usize) -> Result<usize> {
        let mut n = 0;
        while n < max && !self.done {
            if self.count == 0 && !self.next_packet()? {
                self.done = true;
                break;
            }
            let take = self.count.min(max - n);
            // `take` events are present in the decoded packet (checked against its length). Each
            // column is appended in one pass over the exact 16-byte records (no zero-fill first).
            let records = &self.packet[self.cursor..self.cursor + 16 * take];
            let base = out.t.len();
            let field = |b: &[u8], at: usize| i16::from_le_bytes([b[at], b[at + 1]]);
            out.t.extend(
                records
                    .chunks_exact(16)
                    .map(|b| i64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]])),
            );
            out.x
                .extend(records.chunks_exact(16).map(|b| field(b, 8) as u16));
            out.y
                .extend(records.chunks_exact(16).map(|b| field(b, 10) as u16));
            out.p.extend(
                records
                    .chunks_exact(16)
                    .map(|b| if b[12] != 0 { 1 } else { -1 }),
            );
            let negative = out.x[base..]
                .iter()
                .zip(&out.y[base..])
                .fold(0u16, |bits, (&x, &y)| bits | x | y)
                > i16::MAX as u16;
            if negative {
                let k = (base..base + take)
                    .find(|&i| out.x[i] > i16::MAX as u16 || out.y[i] > i16::MAX as u16)
                    .unwrap_or(base);
                let (t, x, y) = (out.t[k], out.x[k] as i16, out.y[k] as i16);
                out.truncate(base);
                return Err(EventsError::format(
                    &self.path,
                    format!("event at t={t} us has negative coordinate ({x}, {y})"),
                ));
            }
            // Events inside the stated sensor, in time order (across packets too).
            if let Some(s) = self.sensor {
                let (mx, my) = out.x[base..]
                    .iter()
                    .zip(&out.y[base..])
                    .fold((0u16, 0u16), |(a, b), (&x, &y)| (a.max(x), b.max(y)));
                if u32::from(mx) >= s.width || u32::from(my) >= s.height {
                    let k = (base..base + take)
                        .find(|&i| {
                            u32::from(out.x[i]) >= s.width || u32::from(out.y[i]) >= s.height
                        })
                        .unwrap_or(base);
                    let (t, x, y) = (out.t[k], out.x[k], out.y[k]);
                    out.truncate(base);
                    return Err(EventsError::format(
                        &self.path,
                        format!(
                            "event at t={t} us lies at ({x}, {y}), outside the {}x{} sensor the description states",
                            s.width, s.height
                        ),
                    ));
                }
            }
            let mut last = self.last_t;
            if let Some(k) = (base..base + take).find(|&i| {
                let back = out.t[i] < last;
                last = out.t[i];
                back
            }) {
                let (before, t) = (if k > base { out.t[k - 1] } else { self.last_t }, out.t[k]);
                out.truncate(base);
                return Err(EventsError::format(
                    &self.path,
                    format!("event time goes back from {before} us to {t} us (events must be in time order)"),
                ));
            }
            self.last_t = last;
            self.cursor += 16 * take;
            self.count -= take;
            n += take;
        }
        Ok(n)
    }

    fn bytes_read(&self) -> u64 {
        // Packets read ahead count once they are handed out (their events decoded).
        self.position - self.unconsumed_bytes
    }

    fn total_bytes(&self) -> Option<u64> {
        Some(self.file_len)
    }
}

pub(super) fn ioheader_bytes(compression: Compression, description: &str) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&24u32.to_le_bytes()); // root table at 24
    b.extend_from_slice(b"IOHE");
    for v in [10u16, 20, 4, 8, 16] {
        b.extend_from_slice(&v.to_le_bytes()); // vtable at 8: size, table size, 3 field offsets
    }
    b.resize(24, 0);
    b.extend_from_slice(&16i32.to_le_bytes()); // table - vtable
    b.extend_from_slice(&(compression as i32).to_le_bytes());
    b.extend_from_slice(&(-1i64).to_le_bytes());
    b.extend_from_slice(&4u32.to_le_bytes()); // string at 40 + 4 = 44
    b.extend_from_slice(&(description.len() as u32).to_le_bytes());
    b.extend_from_slice(description.as_bytes());
    b.push(0);
    while b.len() % 4 != 0 {
        b.push(0);
    }
    b
}

pub(super) fn event_packet_bytes(ev: &EventStream, range: std::ops::Range<usize>) -> Vec<u8> {
    let n = range.len();
    let mut b = Vec::with_capacity(32 + 16 * n);
    b.extend_from_slice(&((28 + 16 * n) as u32).to_le_bytes()); // size prefix
    b.extend_from_slice(&16u32.to_le_bytes()); // root table at 4 + 16 = 20
    b.extend_from_slice(b"EVTS");
    for v in [6u16, 8, 4] {
        b.extend_from_slice(&v.to_le_bytes()); // vtable at 12
    }
    b.extend_from_slice(&[0, 0]);
    b.extend_from_slice(&8i32.to_le_bytes()); // table at 20, vtable at 12
    b.extend_from_slice(&4u32.to_le_bytes()); // vector at 24 + 4 = 28
    b.extend_from_slice(&(n as u32).to_le_bytes());
    for i in range {
        b.extend_from_slice(&ev.t[i].to_le_bytes());
        b.extend_from_slice(&(ev.x[i] as i16).to_le_bytes());
        b.extend_from_slice(&(ev.y[i] as i16).to_le_bytes());
        b.extend_from_slice(&[u8::from(ev.p[i] > 0), 0, 0, 0]);
    }
    b
}

/// A packet payload compressed as the file says (`path` names the file in errors).
pub(super) fn compress(compression: Compression, raw: Vec<u8>, path: &Path) -> Result<Vec<u8>> {
    let io = |e: std::io::Error| EventsError::io(path, e);
    Ok(match compression {
        Compression::None => raw,
        Compression::Lz4 | Compression::Lz4High => {
            let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
            enc.write_all(&raw).map_err(io)?;
            enc.finish()
                .map_err(|e| EventsError::format(path, format!("LZ4 encode: {e}")))?
        }
        Compression::Zstd | Compression::ZstdHigh => {
            let level = if compression == Compression::ZstdHigh {
                19
            } else {
                3
            };
            // One-shot compression: the frame header states the decompressed size, which lets
            // readers decode it in one call.
            zstd::bulk::compress(&raw, level).map_err(io)?
        }
    })
}

/// Writes an AEDAT 4 file with one EVTS stream (id 0), packets of up to 8192 events, the given
/// compression, and the sensor size in the description (the stream's, else the events' bounding
/// box). Coordinates must fit i16.
pub fn write_aedat4(
    path: impl AsRef<Path>,
    events: &EventStream,
    compression: Compression,
) -> Result<()> {
    let path = path.as_ref();
    let io = |e: std::io::Error| EventsError::io(path, e);
    if let Some(i) =
        (0..events.len()).find(|&i| events.x[i] > i16::MAX as u16 || events.y[i] > i16::MAX as u16)
    {
        return Err(EventsError::arg(
            "events",
            format!(
                "event {i} at ({}, {}) does not fit AEDAT 4 i16 coordinates",
                events.x[i], events.y[i]
            ),
        ));
    }
    let size = events
        .sensor
        .or_else(|| events.bounding_sensor())
        .unwrap_or(SensorSize::new(1, 1));
    let name = compression.name();
    let desc = format!(
        "<dv version=\"2.0\"><node name=\"outInfo\" path=\"/mainloop/Recorder/outInfo/\">\
         <node name=\"0\" path=\"/mainloop/Recorder/outInfo/0/\">\
         <attr key=\"compression\" type=\"string\">{name}</attr>\
         <attr key=\"originalModuleName\" type=\"string\">events</attr>\
         <attr key=\"originalOutputName\" type=\"string\">events</attr>\
         <attr key=\"typeDescription\" type=\"string\">Array of events (polarity ON/OFF).</attr>\
         <attr key=\"typeIdentifier\" type=\"string\">EVTS</attr>\
         <node name=\"info\" path=\"/mainloop/Recorder/outInfo/0/info/\">\
         <attr key=\"sizeX\" type=\"int\">{}</attr><attr key=\"sizeY\" type=\"int\">{}</attr>\
         <attr key=\"source\" type=\"string\">events crate</attr></node></node></node></dv>",
        size.width, size.height
    );
    let f = File::create(path).map_err(io)?;
    let mut w = BufWriter::with_capacity(1 << 20, f);
    w.write_all(MAGIC).map_err(io)?;
    let h = ioheader_bytes(compression, &desc);
    w.write_all(&(h.len() as u32).to_le_bytes()).map_err(io)?;
    w.write_all(&h).map_err(io)?;
    let mut start = 0;
    while start < events.len() {
        let end = (start + 8192).min(events.len());
        let raw = event_packet_bytes(events, start..end);
        let payload = compress(compression, raw, path)?;
        w.write_all(&0u32.to_le_bytes()).map_err(io)?;
        w.write_all(&(payload.len() as u32).to_le_bytes())
            .map_err(io)?;
        w.write_all(&payload).map_err(io)?;
        start = end;
    }
    w.flush().map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn payload() -> Vec<u8> {
        (0..100_000u32)
            .flat_map(|i| (i / 7).to_le_bytes())
            .collect()
    }

    #[test]
    fn zstd_frames_with_and_without_a_stated_size_decompress_alike() {
        let raw = payload();
        let sized = zstd::bulk::compress(&raw, 3).expect("bulk");
        let streamed = zstd::stream::encode_all(&raw[..], 3).expect("stream");
        assert!(zstd::zstd_safe::get_frame_content_size(&sized)
            .ok()
            .flatten()
            .is_some());
        assert_eq!(
            zstd::zstd_safe::get_frame_content_size(&streamed)
                .ok()
                .flatten(),
            None
        );
        let mut ctx = zstd::zstd_safe::DCtx::try_create();
        for frame in [&sized, &streamed] {
            let mut out = Vec::new();
            decompress(Compression::Zstd, frame, ctx.as_mut(), 1 << 24, &mut out).expect("zstd");
            assert_eq!(out, raw);
        }
        // Over the cap: the streaming path stops at the cap, whatever the header says.
        let mut out = Vec::new();
        decompress(Compression::Zstd, &sized, ctx.as_mut(), 1000, &mut out).expect("capped");
        assert_eq!(out.len(), 1000);
    }
}
