//! Prophesee event files: EVT 2.0 and EVT 3.0 `.raw` and the older `.dat`.
//!
//! All start with an ASCII header of lines beginning with `%` (sensor size from `% geometry WxH`,
//! `% format EVT3;height=H;width=W` or `% Width W` / `% Height H`; the encoding from `% evt 2.0|3.0`
//! or `format EVT2|EVT3`). Then, little-endian:
//! - EVT 2.0: 32-bit words, type in bits 31..28: CD_OFF 0x0 / CD_ON 0x1 with t low bits 27..22,
//!   x 21..11, y 10..0; EVT_TIME_HIGH 0x8 with t bits 33..6 in 27..0; others skipped.
//! - EVT 3.0: 16-bit words, type in bits 15..12: ADDR_Y 0x0 (y 10..0), ADDR_X 0x2 (pol 11, x 10..0,
//!   one event), VECT_BASE_X 0x3 (pol 11, x 10..0), VECT_12 0x4 / VECT_8 0x5 (validity masks of 12 / 8
//!   consecutive x, then base x advances), TIME_LOW 0x6 and TIME_HIGH 0x8 (12 bits each of a
//!   24-bit µs counter; wrap-arounds of TIME_HIGH are unrolled); others skipped.
//! - `.dat`: after the header, one byte event type and one byte event size (8), then records
//!   {u32 t µs, u32 data} with x = bits 13..0, y = bits 27..14, p = bits 31..28.
//!
//! Decoders keep their state across chunks; a trailing partial word is an error.
//!
//! Writers ([`write_raw`], [`write_dat`]) produce exactly what the reader decodes: EVT 2.0 emits
//! EVT_TIME_HIGH whenever `t >> 6` changes; EVT 3.0 emits TIME_HIGH / TIME_LOW / ADDR_Y only when
//! they change, one ADDR_X per event (no vector words), and makes every wrap of the 24-bit counter
//! visible to the reader (a TIME_HIGH 0xFFF then 0x000 per wrap), so streams longer than 2^24 µs
//! round-trip. They refuse what a format cannot hold (coordinates beyond 11 / 14 bits, negative or
//! too large times, decreasing times in EVT 3.0) with [`EventsError::InvalidArgument`].

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use super::EventReader;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

/// Encoding of a Prophesee file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PropheseeFormat {
    /// EVT 2.0 `.raw` (32-bit words).
    Evt2,
    /// EVT 3.0 `.raw` (16-bit words).
    Evt3,
    /// `.dat` (8-byte records).
    Dat,
}

/// Largest header accepted (bytes).
const MAX_HEADER: usize = 1 << 20;

/// Reads the `%` header lines; returns them and the number of bytes consumed.
fn read_header(r: &mut impl BufRead, path: &Path) -> Result<(Vec<String>, u64)> {
    let mut lines = Vec::new();
    let mut consumed = 0u64;
    loop {
        let buf = r.fill_buf().map_err(|e| EventsError::io(path, e))?;
        if buf.first() != Some(&b'%') {
            break;
        }
        let mut line = Vec::new();
        let n = r
            .by_ref()
            .take(4096)
            .read_until(b'\n', &mut line)
            .map_err(|e| EventsError::io(path, e))?;
        consumed += n as u64;
        if consumed as usize > MAX_HEADER || line.last() != Some(&b'\n') {
            return Err(EventsError::format(
                path,
                "header line longer than 4096 bytes or unterminated",
            ));
        }
        let text = String::from_utf8_lossy(&line).trim().to_string();
        let end = text == "% end";
        lines.push(text);
        if end {
            break;
        }
    }
    Ok((lines, consumed))
}

fn header_sensor(lines: &[String]) -> Option<SensorSize> {
    let (mut w, mut h) = (None, None);
    for l in lines {
        let body = l.trim_start_matches('%').trim();
        let lower = body.to_ascii_lowercase();
        if let Some(g) = lower.strip_prefix("geometry") {
            if let Some((a, b)) = g.trim().split_once('x') {
                w = a.trim().parse::<u32>().ok().or(w);
                h = b.trim().parse::<u32>().ok().or(h);
            }
        }
        for part in lower.split([';', ' ']) {
            if let Some(v) = part.strip_prefix("width=") {
                w = v.parse().ok().or(w);
            }
            if let Some(v) = part.strip_prefix("height=") {
                h = v.parse().ok().or(h);
            }
        }
        if let Some(v) = lower.strip_prefix("width ") {
            w = v.trim().parse().ok().or(w);
        }
        if let Some(v) = lower.strip_prefix("height ") {
            h = v.trim().parse().ok().or(h);
        }
    }
    match (w, h) {
        (Some(w), Some(h)) if w > 0 && h > 0 && w <= 65536 && h <= 65536 => {
            Some(SensorSize::new(w, h))
        }
        _ => None,
    }
}

fn header_format(lines: &[String]) -> Option<PropheseeFormat> {
    for l in lines {
        let lower = l.to_ascii_lowercase();
        if lower.contains("evt 3") || lower.contains("evt3") {
            return Some(PropheseeFormat::Evt3);
        }
        if lower.contains("evt 2") || lower.contains("evt2") {
            return Some(PropheseeFormat::Evt2);
        }
    }
    None
}

/// Streaming reader of Prophesee `.raw` (EVT 2.0 / 3.0) and `.dat` files.
pub struct PropheseeReader<R: BufRead> {
    reader: R,
    path: PathBuf,
    format: PropheseeFormat,
    sensor: Option<SensorSize>,
    buf: Vec<u8>,
    bytes: u64,
    total: Option<u64>,
    // EVT 2.0 state.
    time_high2: i64,
    // EVT 3.0 state.
    y: u16,
    base_x: u16,
    pol: i8,
    time_low: i64,
    time_high: i64,
    time_high_seen: bool,
    wraps: i64,
    eof: bool,
}

impl PropheseeReader<BufReader<File>> {
    /// Opens a `.raw` (EVT 2.0/3.0 from its header, EVT 3.0 when unstated) or `.dat` file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
        let total = f.metadata().ok().map(|m| m.len());
        let dat = crate::flowio::extension(path) == "dat";
        let mut r = Self::new(BufReader::with_capacity(1 << 20, f), path, dat)?;
        r.total = total;
        Ok(r)
    }
}

impl<R: BufRead> PropheseeReader<R> {
    /// A reader over any buffered source; `dat` selects the `.dat` layout, otherwise the header
    /// decides between EVT 2.0 and EVT 3.0 (default EVT 3.0).
    pub fn new(mut reader: R, path: impl AsRef<Path>, dat: bool) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let (lines, mut consumed) = read_header(&mut reader, &path)?;
        let sensor = header_sensor(&lines);
        let format = if dat {
            let mut tb = [0u8; 2];
            reader
                .read_exact(&mut tb)
                .map_err(|_| EventsError::format(&path, "truncated .dat event type/size bytes"))?;
            consumed += 2;
            if tb[1] != 8 {
                return Err(EventsError::format(
                    &path,
                    format!(".dat event size {} is not 8", tb[1]),
                ));
            }
            PropheseeFormat::Dat
        } else {
            header_format(&lines).unwrap_or(PropheseeFormat::Evt3)
        };
        Ok(Self {
            reader,
            path,
            format,
            sensor,
            buf: Vec::new(),
            bytes: consumed,
            total: None,
            time_high2: 0,
            y: 0,
            base_x: 0,
            pol: 1,
            time_low: 0,
            time_high: 0,
            time_high_seen: false,
            wraps: 0,
            eof: false,
        })
    }

    /// Encoding of the file.
    pub fn encoding(&self) -> PropheseeFormat {
        self.format
    }

    fn word_size(&self) -> usize {
        match self.format {
            PropheseeFormat::Evt2 => 4,
            PropheseeFormat::Evt3 => 2,
            PropheseeFormat::Dat => 8,
        }
    }

    fn decode(&mut self, out: &mut EventStream) -> usize {
        let before = out.len();
        // At most one event per word except EVT 3.0 vectors: bounded by the bytes actually read.
        let words = self.buf.len() / self.word_size();
        out.t.reserve(words);
        out.x.reserve(words);
        out.y.reserve(words);
        out.p.reserve(words);
        // Events are gathered in a fixed local block and appended to the columns a block at a time.
        let mut block = Block::new();
        match self.format {
            PropheseeFormat::Evt2 => {
                for c in self.buf.chunks_exact(4) {
                    block.make_room(out);
                    let w = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    match w >> 28 {
                        0x0 | 0x1 => block.put(
                            (self.time_high2 << 6) | ((w >> 22) & 0x3F) as i64,
                            ((w >> 11) & 0x7FF) as u16,
                            (w & 0x7FF) as u16,
                            if w >> 28 == 1 { 1 } else { -1 },
                            true,
                        ),
                        0x8 => self.time_high2 = (w & 0x0FFF_FFFF) as i64,
                        _ => {}
                    }
                }
            }
            PropheseeFormat::Evt3 => {
                // The decoder state lives in locals for the loop (the current time is kept
                // assembled and only recomputed when a time word arrives) and is stored back after.
                let (mut y, mut base_x, mut pol) = (self.y, self.base_x, self.pol);
                let (mut time_low, mut time_high) = (self.time_low, self.time_high);
                let (mut seen, mut wraps) = (self.time_high_seen, self.wraps);
                let mut t = (wraps << 24) | (time_high << 12) | time_low;
                for c in self.buf.chunks_exact(2) {
                    block.make_room(out);
                    let w = u16::from_le_bytes([c[0], c[1]]);
                    let payload = w & 0x0FFF;
                    match w >> 12 {
                        0x0 => y = payload & 0x7FF,
                        0x2 => block.put(
                            t,
                            payload & 0x7FF,
                            y,
                            if payload & 0x800 != 0 { 1 } else { -1 },
                            true,
                        ),
                        0x3 => {
                            base_x = payload & 0x7FF;
                            pol = if payload & 0x800 != 0 { 1 } else { -1 };
                        }
                        0x4 | 0x5 => {
                            let n = if w >> 12 == 0x4 { 12 } else { 8 };
                            for i in 0..n {
                                let valid = payload & (1 << i) != 0;
                                block.put(t, base_x.wrapping_add(i), y, pol, valid);
                            }
                            base_x = base_x.wrapping_add(n);
                        }
                        0x6 => {
                            time_low = payload as i64;
                            t = (wraps << 24) | (time_high << 12) | time_low;
                        }
                        0x8 => {
                            let high = payload as i64;
                            if seen && high < time_high {
                                wraps += 1;
                            }
                            time_high = high;
                            seen = true;
                            t = (wraps << 24) | (time_high << 12) | time_low;
                        }
                        _ => {}
                    }
                }
                (self.y, self.base_x, self.pol) = (y, base_x, pol);
                (self.time_low, self.time_high) = (time_low, time_high);
                (self.time_high_seen, self.wraps) = (seen, wraps);
            }
            PropheseeFormat::Dat => {
                for c in self.buf.chunks_exact(8) {
                    block.make_room(out);
                    let t = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    let d = u32::from_le_bytes([c[4], c[5], c[6], c[7]]);
                    block.put(
                        t as i64,
                        (d & 0x3FFF) as u16,
                        ((d >> 14) & 0x3FFF) as u16,
                        if (d >> 28) & 0xF != 0 { 1 } else { -1 },
                        true,
                    );
                }
            }
        }
        block.flush(out);
        out.len() - before
    }
}

/// Events per [`Block`].
const BLOCK: usize = 1024;
/// Most events one word can add (an EVT 3.0 VECT_12 word).
const MAX_EVENTS_PER_WORD: usize = 12;

/// A fixed block of decoded events on the stack, appended to the output columns when full: the
/// decoders' inner loops then store into plain arrays instead of growing four `Vec`s per event.
struct Block {
    t: [i64; BLOCK],
    x: [u16; BLOCK],
    y: [u16; BLOCK],
    p: [i8; BLOCK],
    len: usize,
}

impl Block {
    fn new() -> Self {
        Self {
            t: [0; BLOCK],
            x: [0; BLOCK],
            y: [0; BLOCK],
            p: [0; BLOCK],
            len: 0,
        }
    }

    /// Flushes the block if the next word could overflow it.
    #[inline(always)]
    fn make_room(&mut self, out: &mut EventStream) {
        if self.len > BLOCK - MAX_EVENTS_PER_WORD {
            self.flush(out);
        }
    }

    /// Writes an event at the end of the block and keeps it iff `valid` (branch-free, so that
    /// vector words with random masks cost no mispredictions). Needs room (see [`Self::make_room`]).
    #[inline(always)]
    fn put(&mut self, t: i64, x: u16, y: u16, p: i8, valid: bool) {
        let k = self.len.min(BLOCK - 1);
        self.t[k] = t;
        self.x[k] = x;
        self.y[k] = y;
        self.p[k] = p;
        self.len = k + usize::from(valid);
    }

    /// Appends the block's events to `out` and empties it.
    fn flush(&mut self, out: &mut EventStream) {
        out.t.extend_from_slice(&self.t[..self.len]);
        out.x.extend_from_slice(&self.x[..self.len]);
        out.y.extend_from_slice(&self.y[..self.len]);
        out.p.extend_from_slice(&self.p[..self.len]);
        self.len = 0;
    }
}

impl<R: BufRead> EventReader for PropheseeReader<R> {
    fn format(&self) -> &'static str {
        match self.format {
            PropheseeFormat::Evt2 => "evt2",
            PropheseeFormat::Evt3 => "evt3",
            PropheseeFormat::Dat => "dat",
        }
    }

    fn sensor(&self) -> Option<SensorSize> {
        self.sensor
    }

    fn read_chunk(&mut self, out: &mut EventStream, max: usize) -> Result<usize> {
        // Decode whole words in blocks; EVT 3.0 vectors may yield up to 12 events per word, so a
        // chunk can exceed `max` by at most one block's vector events.
        let ws = self.word_size();
        let mut n = 0;
        while n < max && !self.eof {
            let words = ((max - n) / if ws == 2 { 4 } else { 1 }).clamp(1, 1 << 16);
            self.buf.resize(words * ws, 0);
            let got = super::read_full(&mut self.reader, &mut self.buf)
                .map_err(|e| EventsError::io(&self.path, e))?;
            self.bytes += got as u64;
            if got % ws != 0 {
                return Err(EventsError::format(
                    &self.path,
                    format!("truncated {}-byte word at the end of the file", ws),
                ));
            }
            self.buf.truncate(got);
            if got < words * ws {
                self.eof = true;
            }
            n += self.decode(out);
        }
        Ok(n)
    }

    fn bytes_read(&self) -> u64 {
        self.bytes
    }

    fn total_bytes(&self) -> Option<u64> {
        self.total
    }
}

/// Largest coordinate of EVT 2.0 / EVT 3.0 words (11 bits).
const MAX_COORD_EVT: u16 = 0x7FF;
/// Largest coordinate of `.dat` records (14 bits).
const MAX_COORD_DAT: u16 = 0x3FFF;

/// Checks that every coordinate is at most `max` and every time lies in `0..=t_max` (µs); for
/// EVT 3.0 (`sorted`) also that times do not decrease.
fn check_writable(
    events: &EventStream,
    max: u16,
    t_max: i64,
    sorted: bool,
    what: &str,
) -> Result<()> {
    for i in 0..events.len() {
        let (x, y, t) = (events.x[i], events.y[i], events.t[i]);
        if x > max || y > max {
            return Err(EventsError::arg(
                "events",
                format!("event {i} at ({x}, {y}) does not fit {what} coordinates (at most {max})"),
            ));
        }
        if !(0..=t_max).contains(&t) {
            return Err(EventsError::arg(
                "events",
                format!("event {i} time {t} us is outside the {what} range 0..={t_max} us"),
            ));
        }
        if sorted && i > 0 && t < events.t[i - 1] {
            return Err(EventsError::NonMonotonic {
                index: i,
                previous_us: events.t[i - 1],
                t_us: t,
            });
        }
    }
    Ok(())
}

/// Sensor size written to the header: the stream's, else the events' bounding box, else 1x1.
fn header_size(events: &EventStream) -> SensorSize {
    events
        .sensor
        .or_else(|| events.bounding_sensor())
        .unwrap_or(SensorSize::new(1, 1))
}

/// Bytes buffered by the encoders before they hand them to the sink.
const ENCODE_BLOCK: usize = 1 << 20;

/// A byte buffer that drains into `sink` whenever it holds [`ENCODE_BLOCK`] bytes.
struct Blocks<'w, W: Write> {
    buf: Vec<u8>,
    sink: &'w mut W,
}

impl<W: Write> Blocks<'_, W> {
    #[inline]
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.buf.extend_from_slice(bytes);
        if self.buf.len() >= ENCODE_BLOCK {
            self.sink.write_all(&self.buf)?;
            self.buf.clear();
        }
        Ok(())
    }

    fn finish(self) -> std::io::Result<()> {
        self.sink.write_all(&self.buf)
    }
}

/// Encodes EVT 2.0 words (after the header); the events must have passed [`check_writable`] with
/// 11-bit coordinates and times below 2^34 µs.
fn encode_evt2(events: &EventStream, out: &mut Blocks<'_, impl Write>) -> std::io::Result<()> {
    let mut high = -1i64;
    for i in 0..events.len() {
        let t = events.t[i];
        if t >> 6 != high {
            high = t >> 6;
            out.put(&((0x8u32 << 28) | (high as u32 & 0x0FFF_FFFF)).to_le_bytes())?;
        }
        let ty = u32::from(events.p[i] > 0);
        let w = (ty << 28)
            | (((t & 0x3F) as u32) << 22)
            | ((events.x[i] as u32) << 11)
            | events.y[i] as u32;
        out.put(&w.to_le_bytes())?;
    }
    Ok(())
}

/// Encodes EVT 3.0 words (after the header); the events must have passed [`check_writable`] with
/// 11-bit coordinates and non-negative, non-decreasing times.
fn encode_evt3(events: &EventStream, out: &mut Blocks<'_, impl Write>) -> std::io::Result<()> {
    let mut push = |w: u16| out.put(&w.to_le_bytes());
    // Mirror of the reader state: absolute time-high (t >> 12, wraps included), low 12 bits, row;
    // `None` = not emitted yet.
    let mut high: Option<i64> = None;
    let mut low: Option<i64> = None;
    let mut row: Option<u16> = None;
    for i in 0..events.len() {
        let t = events.t[i];
        let h = t >> 12;
        if high != Some(h) {
            // The reader counts a wrap each time TIME_HIGH decreases: per wrap, go up to 0xFFF
            // (never a decrease) and back to 0 (one decrease), then to the target value.
            let wraps_done = high.map_or(0, |p| p >> 12);
            let mut cur = high.map(|p| p & 0xFFF);
            for _ in wraps_done..(h >> 12) {
                if cur != Some(0xFFF) {
                    push(0x8FFF)?;
                }
                push(0x8000)?;
                cur = Some(0);
            }
            if cur != Some(h & 0xFFF) {
                push((0x8 << 12) | (h & 0xFFF) as u16)?;
            }
            high = Some(h);
        }
        if low != Some(t & 0xFFF) {
            push((0x6 << 12) | (t & 0xFFF) as u16)?;
            low = Some(t & 0xFFF);
        }
        if row != Some(events.y[i]) {
            push(events.y[i])?;
            row = Some(events.y[i]);
        }
        push((0x2 << 12) | (u16::from(events.p[i] > 0) << 11) | events.x[i])?;
    }
    Ok(())
}

/// Encodes `.dat` records (after the header and the type/size bytes); the events must have passed
/// [`check_writable`] with 14-bit coordinates and times up to `u32::MAX` µs.
fn encode_dat(events: &EventStream, out: &mut Blocks<'_, impl Write>) -> std::io::Result<()> {
    for i in 0..events.len() {
        let d = (events.x[i] as u32)
            | ((events.y[i] as u32) << 14)
            | (u32::from(events.p[i] > 0) << 28);
        let mut rec = [0u8; 8];
        rec[..4].copy_from_slice(&(events.t[i] as u32).to_le_bytes());
        rec[4..].copy_from_slice(&d.to_le_bytes());
        out.put(&rec)?;
    }
    Ok(())
}

/// Checks `events` against the limits of `format` and returns its header bytes.
fn check_and_header(events: &EventStream, format: PropheseeFormat) -> Result<Vec<u8>> {
    let size = header_size(events);
    Ok(match format {
        PropheseeFormat::Evt2 => {
            check_writable(events, MAX_COORD_EVT, (1i64 << 34) - 1, false, "EVT 2.0")?;
            format!(
                "% evt 2.0\n% geometry {}x{}\n% end\n",
                size.width, size.height
            )
            .into_bytes()
        }
        PropheseeFormat::Evt3 => {
            check_writable(events, MAX_COORD_EVT, i64::MAX, true, "EVT 3.0")?;
            format!(
                "% evt 3.0\n% format EVT3;height={};width={}\n% end\n",
                size.height, size.width
            )
            .into_bytes()
        }
        PropheseeFormat::Dat => {
            check_writable(events, MAX_COORD_DAT, u32::MAX as i64, false, ".dat")?;
            let mut h = format!(
                "% Data file containing CD events.\n% Width {}\n% Height {}\n",
                size.width, size.height
            )
            .into_bytes();
            h.extend_from_slice(&[0x0C, 8]);
            h
        }
    })
}

/// Encodes a checked stream (header already written) into `sink`.
fn encode_body(
    events: &EventStream,
    format: PropheseeFormat,
    sink: &mut impl Write,
) -> std::io::Result<()> {
    let mut out = Blocks {
        buf: Vec::with_capacity(ENCODE_BLOCK + 64),
        sink,
    };
    match format {
        PropheseeFormat::Evt2 => encode_evt2(events, &mut out)?,
        PropheseeFormat::Evt3 => encode_evt3(events, &mut out)?,
        PropheseeFormat::Dat => encode_dat(events, &mut out)?,
    }
    out.finish()
}

/// Encodes a whole Prophesee file (header and body) in memory. Times in µs; polarity > 0 is ON,
/// anything else OFF. Errors: [`EventsError::InvalidArgument`] for coordinates beyond 2047
/// (EVT 2.0 / 3.0) or 16383 (`.dat`), negative times, times from 2^34 µs (EVT 2.0) or above
/// `u32::MAX` µs (`.dat`); [`EventsError::NonMonotonic`] for decreasing times in EVT 3.0.
pub fn encode(events: &EventStream, format: PropheseeFormat) -> Result<Vec<u8>> {
    let mut out = check_and_header(events, format)?;
    encode_body(events, format, &mut out).map_err(|e| EventsError::io("<memory>", e))?;
    Ok(out)
}

/// Writes `events` as a Prophesee `.raw` file in EVT 2.0 or EVT 3.0 ([`PropheseeFormat::Dat`] is
/// accepted too and writes the `.dat` layout). The header states the sensor size (the stream's,
/// else the events' bounding box). Nothing is created when the events do not fit the format; see
/// [`encode`] for the limits.
pub fn write_raw(
    path: impl AsRef<Path>,
    events: &EventStream,
    format: PropheseeFormat,
) -> Result<()> {
    let path = path.as_ref();
    let header = check_and_header(events, format)?;
    let f = File::create(path).map_err(|e| EventsError::io(path, e))?;
    let mut w = BufWriter::new(f);
    w.write_all(&header)
        .and_then(|()| encode_body(events, format, &mut w))
        .and_then(|()| w.flush())
        .map_err(|e| EventsError::io(path, e))
}

/// Writes `events` as a Prophesee `.dat` file (`% Width` / `% Height` header, event type 0x0C,
/// 8-byte records); times must lie in `0..=u32::MAX` µs and coordinates below 16384.
pub fn write_dat(path: impl AsRef<Path>, events: &EventStream) -> Result<()> {
    write_raw(path, events, PropheseeFormat::Dat)
}
