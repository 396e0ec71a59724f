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

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
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

    #[inline]
    fn t3(&self) -> i64 {
        (self.wraps << 24) | (self.time_high << 12) | self.time_low
    }

    fn decode(&mut self, out: &mut EventStream) -> usize {
        let before = out.len();
        match self.format {
            PropheseeFormat::Evt2 => {
                for c in self.buf.chunks_exact(4) {
                    let w = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    match w >> 28 {
                        0x0 | 0x1 => {
                            out.t
                                .push((self.time_high2 << 6) | ((w >> 22) & 0x3F) as i64);
                            out.x.push(((w >> 11) & 0x7FF) as u16);
                            out.y.push((w & 0x7FF) as u16);
                            out.p.push(if w >> 28 == 1 { 1 } else { -1 });
                        }
                        0x8 => self.time_high2 = (w & 0x0FFF_FFFF) as i64,
                        _ => {}
                    }
                }
            }
            PropheseeFormat::Evt3 => {
                let buf = std::mem::take(&mut self.buf);
                for c in buf.chunks_exact(2) {
                    let w = u16::from_le_bytes([c[0], c[1]]);
                    let payload = w & 0x0FFF;
                    match w >> 12 {
                        0x0 => self.y = payload & 0x7FF,
                        0x2 => {
                            out.t.push(self.t3());
                            out.x.push(payload & 0x7FF);
                            out.y.push(self.y);
                            out.p.push(if payload & 0x800 != 0 { 1 } else { -1 });
                        }
                        0x3 => {
                            self.base_x = payload & 0x7FF;
                            self.pol = if payload & 0x800 != 0 { 1 } else { -1 };
                        }
                        0x4 | 0x5 => {
                            let n = if w >> 12 == 0x4 { 12 } else { 8 };
                            let t = self.t3();
                            for i in 0..n {
                                if payload & (1 << i) != 0 {
                                    out.t.push(t);
                                    out.x.push(self.base_x.wrapping_add(i));
                                    out.y.push(self.y);
                                    out.p.push(self.pol);
                                }
                            }
                            self.base_x = self.base_x.wrapping_add(n);
                        }
                        0x6 => self.time_low = payload as i64,
                        0x8 => {
                            let high = payload as i64;
                            if self.time_high_seen && high < self.time_high {
                                self.wraps += 1;
                            }
                            self.time_high = high;
                            self.time_high_seen = true;
                        }
                        _ => {}
                    }
                }
                self.buf = buf;
            }
            PropheseeFormat::Dat => {
                for c in self.buf.chunks_exact(8) {
                    let t = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    let d = u32::from_le_bytes([c[4], c[5], c[6], c[7]]);
                    out.t.push(t as i64);
                    out.x.push((d & 0x3FFF) as u16);
                    out.y.push(((d >> 14) & 0x3FFF) as u16);
                    out.p.push(if (d >> 28) & 0xF != 0 { 1 } else { -1 });
                }
            }
        }
        out.len() - before
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
