//! Prophesee event files: EVT 2.0 and EVT 3.0 `.raw` and the older `.dat`.
//!
//! All start with an ASCII header of lines beginning with `%` (sensor size from `% geometry WxH`,
//! `% format EVT3;height=H;width=W` or `% Width W` / `% Height H`; the encoding from `% evt 2.0|3.0`
//! or `format EVT2|EVT3`). A `.raw` header that does not state the encoding is refused unless the
//! caller gives it ([`ReadOptions::raw_format`]): random bytes decode as a plausible EVT 3.0
//! stream, so the encoding is never guessed. Then, little-endian:
//! - EVT 2.0: 32-bit words, type in bits 31..28: CD_OFF 0x0 / CD_ON 0x1 with t low bits 27..22,
//!   x 21..11, y 10..0; EVT_TIME_HIGH 0x8 with t bits 33..6 in 27..0 (a drop from the top of the
//!   28-bit counter to its bottom is a loop, unrolled); EXT_TRIGGER 0xA, OTHERS 0xE and
//!   CONTINUED 0xF skipped; the other types are reserved.
//! - EVT 3.0: 16-bit words, type in bits 15..12: ADDR_Y 0x0 (y 10..0), ADDR_X 0x2 (pol 11, x 10..0,
//!   one event), VECT_BASE_X 0x3 (pol 11, x 10..0), VECT_12 0x4 / VECT_8 0x5 (validity masks of 12 / 8
//!   consecutive x, then base x advances), TIME_LOW 0x6 and TIME_HIGH 0x8 (12 bits each of a
//!   24-bit µs counter; wrap-arounds of TIME_HIGH are unrolled); CONTINUED_4 0x7, EXT_TRIGGER 0xA,
//!   OTHERS 0xE and CONTINUED_12 0xF skipped; the other types (0x1, 0x9, 0xB-0xD) are reserved.
//! - `.dat`: after the header, one byte event type and one byte event size (8), then records
//!   {u32 t µs, u32 data} with x = bits 13..0, y = bits 27..14, p = bits 31..28.
//!
//! EVT words are checked as the specifications allow: a reserved type, an event outside the
//! header's sensor (else the 2048-pixel address range), an EVT 3.0 event before any ADDR_Y or
//! vector before any VECT_BASE_X, and a TIME_HIGH below the current one that is not a wrap (only a
//! drop from within 10 steps of the counter's top to its bottom is, as in Prophesee's decoders) are
//! [`EventsError::BadWord`] with the file and the word's byte offset, or, when lenient
//! ([`ReadOptions::lenient`]), skipped and counted. TIME_LOW may step back inside its TIME_HIGH
//! period, and EVT 2.0 events in one period may come in any order of their low time bits: both are
//! legal and decoded as written. Events before the first TIME_HIGH are decoded with TIME_HIGH 0,
//! as before.
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
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

mod decode;
mod write;

use decode::{BadWord, Block};

pub use write::{encode, write_dat, write_raw};

use super::{EventReader, ReadOptions};
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

/// Encoding of the words of a Prophesee `.raw` file, for files whose header does not state it
/// (see [`super::ReadOptions::raw_format`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawEncoding {
    /// EVT 2.0 (32-bit words).
    Evt2,
    /// EVT 3.0 (16-bit words).
    Evt3,
}

impl From<RawEncoding> for PropheseeFormat {
    fn from(e: RawEncoding) -> Self {
        match e {
            RawEncoding::Evt2 => Self::Evt2,
            RawEncoding::Evt3 => Self::Evt3,
        }
    }
}

/// Largest coordinate range of EVT 2.0 / 3.0 (11-bit addresses), in pixels.
const EVT_RANGE: u32 = 2048;

/// A TIME_HIGH that drops by at least its counter's largest value minus this many steps is the
/// counter wrapping around (the rule of Prophesee's own decoders); any smaller drop is time going
/// backwards.
const WRAP_SLACK: i64 = 10;

/// Streaming reader of Prophesee `.raw` (EVT 2.0 / 3.0) and `.dat` files.
///
/// EVT streams are checked word by word as the specifications allow (see the module docs and
/// `docs/FORMATS.md`): a reserved word type, an event outside the header's sensor (or the 2048-pixel
/// address range), an event before any row (EVT 3.0 ADDR_Y), a vector before any base
/// (VECT_BASE_X), or a TIME_HIGH that goes backwards without being a wrap of its counter is an
/// [`EventsError::BadWord`] naming the file and the word's byte offset, unless the reader is
/// lenient: then the word is skipped and counted ([`EventReader::skipped_words`]).
pub struct PropheseeReader<R: BufRead> {
    reader: R,
    path: PathBuf,
    format: PropheseeFormat,
    sensor: Option<SensorSize>,
    buf: Vec<u8>,
    bytes: u64,
    total: Option<u64>,
    /// Skip bad words instead of failing.
    lenient: bool,
    /// Bad words skipped so far (lenient only).
    skipped: u64,
    /// Exclusive bounds of valid columns / rows (the header's sensor, else the address range).
    width: u32,
    height: u32,
    // EVT 2.0 state.
    time_high2: i64,
    time_high2_seen: bool,
    wraps2: i64,
    // EVT 3.0 state.
    y: u16,
    base_x: u16,
    pol: i8,
    row_seen: bool,
    base_seen: bool,
    time_low: i64,
    time_high: i64,
    time_high_seen: bool,
    wraps: i64,
    /// `.dat` decoding state: the last event's time (µs, unwrapped), whether one was seen, and the
    /// wraps of the 32-bit counter.
    dat_last: i64,
    dat_seen: bool,
    dat_wraps: i64,
    eof: bool,
}

impl PropheseeReader<BufReader<File>> {
    /// Opens a `.raw` (EVT 2.0/3.0 as its header states) or `.dat` file with default options: a
    /// `.raw` file whose header does not state its encoding is refused.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        Self::open_with(path, &ReadOptions::default())
    }

    /// Opens a `.raw` or `.dat` file with `options` (the encoding of a `.raw` file whose header
    /// does not state it; lenient decoding).
    pub fn open_with(path: impl AsRef<Path>, options: &ReadOptions) -> Result<Self> {
        let path = path.as_ref();
        let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
        let total = f.metadata().ok().map(|m| m.len());
        let dat = crate::flowio::extension(path) == "dat";
        let mut r = Self::with_options(BufReader::with_capacity(1 << 20, f), path, dat, options)?;
        r.total = total;
        Ok(r)
    }
}

impl<R: BufRead> PropheseeReader<R> {
    /// A reader over any buffered source with default options; `dat` selects the `.dat` layout,
    /// otherwise the header must state EVT 2.0 or EVT 3.0.
    pub fn new(reader: R, path: impl AsRef<Path>, dat: bool) -> Result<Self> {
        Self::with_options(reader, path, dat, &ReadOptions::default())
    }

    /// A reader over any buffered source; `dat` selects the `.dat` layout, otherwise the header
    /// decides between EVT 2.0 and EVT 3.0, or `options.raw_format` when the header does not say.
    /// A header and an option that disagree are refused, as is a header that states nothing
    /// without the option.
    pub fn with_options(
        mut reader: R,
        path: impl AsRef<Path>,
        dat: bool,
        options: &ReadOptions,
    ) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        let (lines, mut consumed) = read_header(&mut reader, &path)?;
        let sensor = header_sensor(&lines);
        let format = if dat {
            if options.raw_format.is_some() {
                return Err(EventsError::arg(
                    "raw_format",
                    format!(
                        "{}: the encoding applies to .raw files only, not to .dat",
                        path.display()
                    ),
                ));
            }
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
            raw_encoding(&lines, options.raw_format, &path)?
        };
        let (width, height) = match sensor {
            Some(s) if format != PropheseeFormat::Dat => {
                (s.width.min(EVT_RANGE), s.height.min(EVT_RANGE))
            }
            _ => (EVT_RANGE, EVT_RANGE),
        };
        Ok(Self {
            reader,
            path,
            format,
            sensor,
            buf: Vec::new(),
            bytes: consumed,
            total: None,
            lenient: options.lenient,
            skipped: 0,
            width,
            height,
            time_high2: 0,
            time_high2_seen: false,
            wraps2: 0,
            y: 0,
            base_x: 0,
            pol: 1,
            row_seen: false,
            base_seen: false,
            time_low: 0,
            time_high: 0,
            time_high_seen: false,
            wraps: 0,
            dat_last: 0,
            dat_seen: false,
            dat_wraps: 0,
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

    /// Decodes the words in `self.buf`, whose first byte is at file offset `offset`; returns the
    /// number of events appended. A bad word is an error (the events before it are appended) or,
    /// when lenient, skipped and counted.
    fn decode(&mut self, out: &mut EventStream, offset: u64) -> Result<usize> {
        let before = out.len();
        let ws = self.word_size();
        // At most one event per word except EVT 3.0 vectors: bounded by the bytes actually read.
        let words = self.buf.len() / ws;
        out.t.reserve(words);
        out.x.reserve(words);
        out.y.reserve(words);
        out.p.reserve(words);
        // Events are gathered in a fixed local block and appended to the columns a block at a time.
        let mut block = Block::new();
        let bad = match self.format {
            PropheseeFormat::Evt2 => self.decode_evt2(&mut block, out),
            PropheseeFormat::Evt3 => self.decode_evt3(&mut block, out),
            PropheseeFormat::Dat => self.decode_dat(&mut block, out),
        };
        block.flush(out);
        match bad {
            Some(BadWord { index, message }) => Err(EventsError::BadWord {
                path: self.path.display().to_string(),
                offset: offset + (index * ws) as u64,
                message,
            }),
            None => Ok(out.len() - before),
        }
    }

    /// The sensor bounds for messages: the header's size, or the address range.
    fn bounds(&self) -> String {
        match self.sensor {
            Some(_) => format!("the header's {}x{} sensor", self.width, self.height),
            None => format!("the {EVT_RANGE}x{EVT_RANGE} address range"),
        }
    }
}

/// The encoding of a `.raw` file: the header's, else `given`; refused when neither says or they
/// disagree.
fn raw_encoding(
    lines: &[String],
    given: Option<RawEncoding>,
    path: &Path,
) -> Result<PropheseeFormat> {
    match (header_format(lines), given.map(PropheseeFormat::from)) {
        (Some(h), Some(g)) if h != g => Err(EventsError::format(
            path,
            format!("the header states {h:?} but {g:?} was given as its encoding"),
        )),
        (Some(f), _) | (None, Some(f)) => Ok(f),
        (None, None) => Err(EventsError::format(
            path,
            "no header line states the encoding of this Prophesee .raw file (`% evt 2.0`, \
             `% evt 3.0` or `% format EVT2|EVT3;...`) and it is not guessed: state it with \
             `--format evt2|evt3` on the event commands or `events_raw_format` in a scene's \
             scene.json (library: `ReadOptions::raw_format`)",
        )),
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
            let offset = self.bytes;
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
            n += self.decode(out, offset)?;
        }
        Ok(n)
    }

    fn bytes_read(&self) -> u64 {
        self.bytes
    }

    fn total_bytes(&self) -> Option<u64> {
        self.total
    }

    fn skipped_words(&self) -> u64 {
        self.skipped
    }
}
