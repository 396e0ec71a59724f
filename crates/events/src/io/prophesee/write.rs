//! Prophesee writers: [`encode`], [`write_raw`] and [`write_dat`] produce exactly what the reader
//! of the parent module decodes (see its documentation for the layouts and the limits each format
//! imposes).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::PropheseeFormat;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

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
