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
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use super::EventReader;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};
use rayon::prelude::*;

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

mod header;
mod write;

pub(super) use header::{find_stream, read_header, Fb};
pub use header::{Compression, MAGIC};
pub use write::write_aedat4;
pub(super) use write::{compress, event_packet_bytes, ioheader_bytes};

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
