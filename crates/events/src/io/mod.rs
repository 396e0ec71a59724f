//! Event-file readers and writers.
//!
//! Every reader streams: it holds a bounded buffer and hands out events in chunks through
//! [`EventReader::read_chunk`], so a multi-gigabyte recording never has to fit in memory twice.
//! Readers never allocate by an unchecked header value, never panic on malformed bytes, and report
//! the sensor size when the file states it. They do not sort or validate the stream as a whole: the
//! caller decides (see [`crate::EventStream::validate`] and [`crate::EventStream::sort_by_time`]).
//! The Prophesee EVT 2.0 / 3.0 reader does check each word as its specification allows (a stream of
//! stateful words decodes garbage into plausible-looking events otherwise), and never guesses the
//! encoding of a `.raw` file whose header does not state it: [`ReadOptions`] gives it.

use std::path::Path;

use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

pub mod aedat4;
pub mod aedat4_frames;
pub mod npz;
pub mod prophesee;
pub mod text;

/// Default number of events per chunk used by [`read_events`].
pub const DEFAULT_CHUNK: usize = 1 << 20;

/// How to read an event file; the default reads every file that states its format and refuses
/// anything malformed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Encoding of a Prophesee `.raw` file whose header does not state it (no `% evt 2.0|3.0` or
    /// `% format EVT2|EVT3` line). `None`: such a file is refused. A header that states a
    /// different encoding is refused too. Only for `.raw` files (an error for other formats).
    pub raw_format: Option<prophesee::RawEncoding>,
    /// Skip the words of a Prophesee EVT 2.0 / 3.0 stream that its specification does not allow
    /// (reserved types, events outside the sensor, events without a row, vectors without a base,
    /// time going backwards) instead of failing at the first; the reader counts them
    /// ([`EventReader::skipped_words`]). Other formats ignore it (their readers refuse malformed
    /// input either way).
    pub lenient: bool,
}

/// A streaming source of events.
pub trait EventReader {
    /// Short format name (`"text"`, `"npz"`, `"aedat4"`, `"evt2"`, `"evt3"`, `"dat"`).
    fn format(&self) -> &'static str;
    /// Sensor size when the file states it.
    fn sensor(&self) -> Option<SensorSize>;
    /// Appends at most `max` events to `out` and returns how many were appended; 0 means the end
    /// of the stream.
    fn read_chunk(&mut self, out: &mut EventStream, max: usize) -> Result<usize>;
    /// Bytes consumed so far (for progress bars; an estimate for compressed sources).
    fn bytes_read(&self) -> u64;
    /// Total size of the source in bytes, when known.
    fn total_bytes(&self) -> Option<u64>;
    /// Bad words skipped so far by a lenient reader ([`ReadOptions::lenient`]); 0 for readers
    /// that never skip.
    fn skipped_words(&self) -> u64 {
        0
    }
}

/// The file formats this crate reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EventFormat {
    /// Text `t x y p` (t in float seconds, p ∈ {0, 1}).
    Text,
    /// `.npz` with arrays `x`, `y`, `t`, `p`.
    Npz,
    /// AEDAT 4 (iniVation DV).
    Aedat4,
    /// Prophesee `.raw` (EVT 2.0 / 3.0, from the header or [`ReadOptions::raw_format`]); [`write_events`] writes EVT 3.0 (use
    /// [`prophesee::write_raw`] for EVT 2.0).
    PropheseeRaw,
    /// Prophesee `.dat` (8-byte records, 14-bit coordinates, u32 µs times).
    PropheseeDat,
}

impl EventFormat {
    /// Guesses the format from the extension (`.txt`, `.csv` → text; `.npz`; `.aedat4`/`.aedat`;
    /// `.raw`; `.dat`).
    pub fn from_path(path: &Path) -> Result<Self> {
        match crate::flowio::extension(path).as_str() {
            "txt" | "csv" | "text" => Ok(Self::Text),
            "npz" => Ok(Self::Npz),
            "aedat4" | "aedat" => Ok(Self::Aedat4),
            "raw" => Ok(Self::PropheseeRaw),
            "dat" => Ok(Self::PropheseeDat),
            other => Err(EventsError::format(
                path,
                format!(
                    "unknown event-file extension {other:?} (expected txt, npz, aedat4, raw, dat)"
                ),
            )),
        }
    }
}

/// Opens a streaming reader, choosing the format from the extension, with default
/// [`ReadOptions`] (a `.raw` file must state its encoding; malformed words are errors).
pub fn open_events(path: impl AsRef<Path>) -> Result<Box<dyn EventReader>> {
    open_events_with(path, &ReadOptions::default())
}

/// Opens a streaming reader, choosing the format from the extension, with `options`. Errors:
/// [`EventsError::InvalidArgument`] for a `raw_format` given with a file that is not `.raw`.
pub fn open_events_with(
    path: impl AsRef<Path>,
    options: &ReadOptions,
) -> Result<Box<dyn EventReader>> {
    let path = path.as_ref();
    let format = EventFormat::from_path(path)?;
    if options.raw_format.is_some() && format != EventFormat::PropheseeRaw {
        return Err(EventsError::arg(
            "raw_format",
            format!(
                "{}: the EVT encoding applies to Prophesee .raw files only",
                path.display()
            ),
        ));
    }
    Ok(match format {
        EventFormat::Text => Box::new(text::TextReader::open(path)?),
        EventFormat::Npz => Box::new(npz::NpzReader::open(path)?),
        EventFormat::Aedat4 => Box::new(aedat4::Aedat4Reader::open(path)?),
        EventFormat::PropheseeRaw | EventFormat::PropheseeDat => {
            Box::new(prophesee::PropheseeReader::open_with(path, options)?)
        }
    })
}

/// Reads every event of a file (format from the extension) with default [`ReadOptions`]; the
/// sensor size is set when stated.
pub fn read_events(path: impl AsRef<Path>) -> Result<EventStream> {
    read_events_with(path, &ReadOptions::default())
}

/// Reads every event of a file (format from the extension) with `options`; the sensor size is set
/// when stated. A lenient read does not say how many words it skipped: open the reader with
/// [`open_events_with`] and ask [`EventReader::skipped_words`] when that matters.
pub fn read_events_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<EventStream> {
    let mut r = open_events_with(path, options)?;
    read_all(r.as_mut())
}

/// Drains a reader into one stream.
///
/// After the first chunk the columns are reserved for the whole source, extrapolated from the
/// events per byte read so far and the source's size (never from a header claim; a refused or
/// wrong estimate only means the columns grow as they go), which saves the copies and page faults
/// of repeated doubling on large files.
pub fn read_all(r: &mut dyn EventReader) -> Result<EventStream> {
    let mut s = EventStream::new();
    if r.read_chunk(&mut s, DEFAULT_CHUNK)? == 0 {
        s.sensor = r.sensor();
        return Ok(s);
    }
    if let (Some(total), read) = (r.total_bytes(), r.bytes_read()) {
        if read > 0 && total > read {
            let estimate = (s.len() as f64 * total as f64 / read as f64 * 1.02) as usize;
            let _ = s.try_reserve(estimate.saturating_sub(s.len()));
        }
    }
    while r.read_chunk(&mut s, DEFAULT_CHUNK)? > 0 {}
    s.sensor = r.sensor();
    Ok(s)
}

/// Writes a stream (format from the extension): text, npz, AEDAT 4 uncompressed, `.raw` as
/// Prophesee EVT 3.0 (times must not decrease), `.dat` as Prophesee DAT. Events a format cannot
/// hold (e.g. coordinates ≥ 2048 in EVT 3.0) are an [`EventsError::InvalidArgument`].
pub fn write_events(path: impl AsRef<Path>, events: &EventStream) -> Result<()> {
    let path = path.as_ref();
    match EventFormat::from_path(path)? {
        EventFormat::Text => text::write_text(path, events),
        EventFormat::Npz => npz::write_npz(path, events),
        EventFormat::Aedat4 => aedat4::write_aedat4(path, events, aedat4::Compression::None),
        EventFormat::PropheseeRaw => {
            prophesee::write_raw(path, events, prophesee::PropheseeFormat::Evt3)
        }
        EventFormat::PropheseeDat => prophesee::write_dat(path, events),
    }
}

/// Reads until `buf` is full or the reader is at end of file, retrying on `Interrupted`; returns the
/// number of bytes read (less than `buf.len()` only at end of file). Shared by the binary readers so a
/// short final record is detected the same way everywhere.
pub(crate) fn read_full(r: &mut impl std::io::Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}
