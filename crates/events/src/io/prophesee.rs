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
use std::io::{BufRead, BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

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
                None
            }
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

    /// Decodes EVT 2.0 words; returns the first bad word (strict) or `None`.
    fn decode_evt2(&mut self, block: &mut Block, out: &mut EventStream) -> Option<BadWord> {
        const TIME_LOOP: i64 = 1 << 28;
        let (width, height) = (self.width, self.height);
        let (mut high, mut seen, mut wraps) = (self.time_high2, self.time_high2_seen, self.wraps2);
        let mut bad = None;
        for (i, c) in self.buf.chunks_exact(4).enumerate() {
            block.make_room(out);
            let w = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            let problem = match w >> 28 {
                0x0 | 0x1 => {
                    let (x, y) = ((w >> 11) & 0x7FF, w & 0x7FF);
                    if x < width && y < height {
                        block.put(
                            (high << 6) | ((w >> 22) & 0x3F) as i64,
                            x as u16,
                            y as u16,
                            if w >> 28 == 1 { 1 } else { -1 },
                            true,
                        );
                        None
                    } else {
                        Some(Problem::Outside(x, y))
                    }
                }
                0x8 => {
                    let value = (w & 0x0FFF_FFFF) as i64;
                    let current = high - wraps * TIME_LOOP;
                    if seen && value < current {
                        if current - value >= TIME_LOOP - 1 - WRAP_SLACK {
                            wraps += 1;
                            high = value + wraps * TIME_LOOP;
                            None
                        } else {
                            Some(Problem::Backwards {
                                from: current,
                                to: value,
                                step_us: 64,
                            })
                        }
                    } else {
                        high = value + wraps * TIME_LOOP;
                        seen = true;
                        None
                    }
                }
                // EXT_TRIGGER, OTHERS, CONTINUED: valid, carry no CD event.
                0xA | 0xE | 0xF => None,
                ty => Some(Problem::Reserved(ty as u16)),
            };
            if let Some(p) = problem {
                if self.lenient {
                    self.skipped += 1;
                } else {
                    bad = Some(BadWord {
                        index: i,
                        message: p.describe(&format!("{w:#010x}"), "EVT 2.0", &self.bounds()),
                    });
                    break;
                }
            }
        }
        (self.time_high2, self.time_high2_seen, self.wraps2) = (high, seen, wraps);
        bad
    }

    /// Decodes EVT 3.0 words; returns the first bad word (strict) or `None`.
    fn decode_evt3(&mut self, block: &mut Block, out: &mut EventStream) -> Option<BadWord> {
        // The decoder state lives in locals for the loop (the current time is kept assembled and
        // only recomputed when a time word arrives) and is stored back after.
        let (width, height) = (self.width, self.height);
        let (mut y, mut base_x, mut pol) = (self.y, self.base_x, self.pol);
        let (mut row_seen, mut base_seen) = (self.row_seen, self.base_seen);
        let (mut time_low, mut time_high) = (self.time_low, self.time_high);
        let (mut seen, mut wraps) = (self.time_high_seen, self.wraps);
        let mut t = (wraps << 24) | (time_high << 12) | time_low;
        let mut bad = None;
        for (i, c) in self.buf.chunks_exact(2).enumerate() {
            block.make_room(out);
            let w = u16::from_le_bytes([c[0], c[1]]);
            let payload = w & 0x0FFF;
            let problem = match w >> 12 {
                0x0 => {
                    y = payload & 0x7FF;
                    row_seen = true;
                    None
                }
                0x2 => {
                    let x = payload & 0x7FF;
                    if !row_seen {
                        Some(Problem::NoRow)
                    } else if u32::from(x) < width && u32::from(y) < height {
                        block.put(t, x, y, if payload & 0x800 != 0 { 1 } else { -1 }, true);
                        None
                    } else {
                        Some(Problem::Outside(u32::from(x), u32::from(y)))
                    }
                }
                0x3 => {
                    base_x = payload & 0x7FF;
                    pol = if payload & 0x800 != 0 { 1 } else { -1 };
                    base_seen = true;
                    None
                }
                0x4 | 0x5 => {
                    let n = if w >> 12 == 0x4 { 12 } else { 8 };
                    let mask = payload & ((1 << n) - 1);
                    // Column of the last valid element (base_x when none is valid).
                    let last = u32::from(base_x) + (15 - mask.leading_zeros().min(15));
                    if !base_seen {
                        Some(Problem::NoBase)
                    } else if !row_seen {
                        Some(Problem::NoRow)
                    } else if mask != 0 && (last >= width || u32::from(y) >= height) {
                        Some(Problem::Outside(last, u32::from(y)))
                    } else {
                        for i in 0..n {
                            let valid = payload & (1 << i) != 0;
                            block.put(t, base_x.wrapping_add(i), y, pol, valid);
                        }
                        base_x = base_x.saturating_add(n);
                        None
                    }
                }
                0x6 => {
                    // Any TIME_LOW is inside the current TIME_HIGH period: small step-backs are
                    // legal.
                    time_low = payload as i64;
                    t = (wraps << 24) | (time_high << 12) | time_low;
                    None
                }
                0x8 => {
                    let high = payload as i64;
                    if seen && high < time_high && time_high - high < 0xFFF - WRAP_SLACK {
                        Some(Problem::Backwards {
                            from: time_high,
                            to: high,
                            step_us: 4096,
                        })
                    } else {
                        if seen && high < time_high {
                            wraps += 1;
                        }
                        time_high = high;
                        seen = true;
                        t = (wraps << 24) | (time_high << 12) | time_low;
                        None
                    }
                }
                // CONTINUED_4, EXT_TRIGGER, OTHERS, CONTINUED_12: valid, carry no CD event.
                0x7 | 0xA | 0xE | 0xF => None,
                ty => Some(Problem::Reserved(ty)),
            };
            if let Some(p) = problem {
                if self.lenient {
                    self.skipped += 1;
                } else {
                    bad = Some(BadWord {
                        index: i,
                        message: p.describe(&format!("{w:#06x}"), "EVT 3.0", &self.bounds()),
                    });
                    break;
                }
            }
        }
        (self.y, self.base_x, self.pol) = (y, base_x, pol);
        (self.row_seen, self.base_seen) = (row_seen, base_seen);
        (self.time_low, self.time_high) = (time_low, time_high);
        (self.time_high_seen, self.wraps) = (seen, wraps);
        bad
    }
}

/// The first bad word of a buffer: its index in the buffer and what is wrong.
struct BadWord {
    index: usize,
    message: String,
}

/// What is wrong with a word (formatted only when it is reported).
enum Problem {
    /// A word type the specification reserves.
    Reserved(u16),
    /// An event at (x, y) outside the sensor.
    Outside(u32, u32),
    /// An EVT 3.0 event before any ADDR_Y.
    NoRow,
    /// An EVT 3.0 vector before any VECT_BASE_X.
    NoBase,
    /// A TIME_HIGH below the current one that is not a wrap; `step_us` is one TIME_HIGH unit.
    Backwards { from: i64, to: i64, step_us: i64 },
}

impl Problem {
    /// The message for `word` (already in hex) of a `format` stream; `bounds` names the sensor.
    fn describe(&self, word: &str, format: &str, bounds: &str) -> String {
        match self {
            Self::Reserved(ty) => format!(
                "{format} word {word} has the reserved type {ty:#x} (not an event-camera stream of \
                 this encoding, or a corrupt one; --lenient skips bad words)"
            ),
            Self::Outside(x, y) => {
                format!("{format} word {word}: event at (x={x}, y={y}) lies outside {bounds}")
            }
            Self::NoRow => format!("{format} word {word}: event before any ADDR_Y word (no row)"),
            Self::NoBase => {
                format!("{format} word {word}: vector before any VECT_BASE_X word (no base)")
            }
            Self::Backwards { from, to, step_us } => format!(
                "{format} word {word}: TIME_HIGH {to:#x} after {from:#x} sends time back by {} us \
                 (a drop is a wrap of the counter only from its top to its bottom)",
                (from - to) * step_us
            ),
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
             `--format evt2|evt3` (library: `ReadOptions::raw_format`)",
        )),
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
