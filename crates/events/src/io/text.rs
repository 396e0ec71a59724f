//! Text events, the Event Camera Dataset layout: one `t x y p` line per event, `t` in float seconds,
//! `p` ∈ {0, 1} (also accepted: -1/+1), separated by spaces, tabs or commas.
//!
//! Optional header: lines starting with `#` or `%` anywhere are comments; a first data line with
//! exactly two integers is the sensor size `width height` (the rpg_e2vid convention); any other
//! first line containing letters is skipped as a column header. Timestamps are converted to microseconds
//! exactly (decimal digits, rounded half up at the 7th decimal), so write → read is lossless.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use super::EventReader;
use crate::error::{EventsError, Result};
use crate::stream::{EventStream, SensorSize};

/// Streaming reader of text events.
pub struct TextReader<R: BufRead> {
    reader: R,
    path: PathBuf,
    line: Vec<u8>,
    line_no: u64,
    seen_data: bool,
    sensor: Option<SensorSize>,
    bytes: u64,
    total: Option<u64>,
    pending: Option<(i64, u16, u16, i8)>,
    /// Line of the pending event.
    pending_line: u64,
    /// The last event's time (µs; `i64::MIN` before the first).
    last_t: i64,
}

impl TextReader<BufReader<File>> {
    /// Opens a text event file; reads the header (sensor line / column header) eagerly.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let f = File::open(path).map_err(|e| EventsError::io(path, e))?;
        let total = f.metadata().ok().map(|m| m.len());
        let mut r = Self::new(BufReader::with_capacity(1 << 20, f), path)?;
        r.total = total;
        Ok(r)
    }
}

impl<R: BufRead> TextReader<R> {
    /// A reader over any buffered source (`path` names it in errors).
    pub fn new(reader: R, path: impl AsRef<Path>) -> Result<Self> {
        let mut r = Self {
            reader,
            path: path.as_ref().to_path_buf(),
            line: Vec::with_capacity(128),
            line_no: 0,
            seen_data: false,
            sensor: None,
            bytes: 0,
            total: None,
            pending: None,
            pending_line: 0,
            last_t: i64::MIN,
        };
        r.read_header()?;
        Ok(r)
    }

    /// Reads the next non-comment line into `self.line`; false at the end.
    fn next_line(&mut self) -> Result<bool> {
        loop {
            self.line.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut self.line)
                .map_err(|e| EventsError::io(&self.path, e))?;
            if n == 0 {
                return Ok(false);
            }
            self.bytes += n as u64;
            self.line_no += 1;
            let first = self.line.iter().find(|c| !c.is_ascii_whitespace());
            match first {
                None | Some(b'#') | Some(b'%') => continue,
                _ => return Ok(true),
            }
        }
    }

    fn read_header(&mut self) -> Result<()> {
        if !self.next_line()? {
            return Ok(());
        }
        let fields: Vec<&[u8]> = split_fields(&self.line).collect();
        if fields.len() == 2 {
            let w = parse_uint(fields[0]);
            let h = parse_uint(fields[1]);
            if let (Some(w), Some(h)) = (w, h) {
                if w == 0 || h == 0 || w > 65536 || h > 65536 {
                    return Err(EventsError::format(
                        &self.path,
                        format!(
                            "sensor line {}: size {w}x{h} outside 1..=65536",
                            self.line_no
                        ),
                    ));
                }
                self.sensor = Some(SensorSize::new(w as u32, h as u32));
                return Ok(());
            }
        }
        match parse_event(&self.line) {
            Some(e) => {
                self.pending = Some(e);
                self.pending_line = self.line_no;
            }
            // A column header such as "t x y p" has letters: skipped.
            None if self.line.iter().any(u8::is_ascii_alphabetic) => {}
            None => {
                let shown =
                    String::from_utf8_lossy(&self.line[..self.line.len().min(80)]).into_owned();
                return Err(EventsError::format(
                    &self.path,
                    format!(
                        "line {}: {:?} is not `t x y p`",
                        self.line_no,
                        shown.trim_end()
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl<R: BufRead> TextReader<R> {
    /// Refuses an event outside the first line's sensor size or earlier than the one before it,
    /// naming the line.
    fn check(&mut self, t: i64, x: u16, y: u16, line: u64) -> Result<()> {
        if let Some(s) = self.sensor {
            if u32::from(x) >= s.width || u32::from(y) >= s.height {
                return Err(EventsError::format(
                    &self.path,
                    format!(
                        "line {line}: event at ({x}, {y}) lies outside the {}x{} sensor of the first line",
                        s.width, s.height
                    ),
                ));
            }
        }
        if t < self.last_t {
            return Err(EventsError::format(
                &self.path,
                format!(
                    "line {line}: time {t} us goes back from {} us (events must be in time order)",
                    self.last_t
                ),
            ));
        }
        self.last_t = t;
        Ok(())
    }
}

fn split_fields(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|&c| c == b' ' || c == b'\t' || c == b',' || c == b'\r' || c == b'\n')
        .filter(|f| !f.is_empty())
}

fn parse_uint(f: &[u8]) -> Option<u64> {
    if f.is_empty() || f.len() > 18 {
        return None;
    }
    let mut v = 0u64;
    for &c in f {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (c - b'0') as u64;
    }
    Some(v)
}

/// Seconds as decimal text → microseconds, exact for up to 6 decimals, rounded half up beyond.
fn parse_seconds_us(f: &[u8]) -> Option<i64> {
    let (int_part, frac) = match f.iter().position(|&c| c == b'.') {
        Some(i) => (&f[..i], &f[i + 1..]),
        None => (f, &f[f.len()..]),
    };
    let fast = !int_part.is_empty()
        && int_part.len() <= 12
        && int_part.iter().all(u8::is_ascii_digit)
        && frac.iter().all(u8::is_ascii_digit);
    if !fast {
        let s = std::str::from_utf8(f).ok()?;
        let v: f64 = s.parse().ok()?;
        let us = (v * 1e6).round();
        return (us.is_finite() && us.abs() < 9.0e18).then_some(us as i64);
    }
    let mut us = parse_uint(int_part)? as i64 * 1_000_000;
    let mut scale = 100_000i64;
    for &c in frac.iter().take(6) {
        us += (c - b'0') as i64 * scale;
        scale /= 10;
    }
    if frac.len() > 6 && frac[6] >= b'5' {
        us += 1;
    }
    Some(us)
}

/// Whitespace/comma tokenizer over one line (hand-rolled: the hot loop of the text reader).
struct Fields<'a> {
    line: &'a [u8],
    pos: usize,
}

impl<'a> Iterator for Fields<'a> {
    type Item = &'a [u8];

    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let sep = |c: u8| c == b' ' || c == b'\t' || c == b',' || c == b'\r' || c == b'\n';
        let l = self.line;
        while self.pos < l.len() && sep(l[self.pos]) {
            self.pos += 1;
        }
        let start = self.pos;
        while self.pos < l.len() && !sep(l[self.pos]) {
            self.pos += 1;
        }
        (self.pos > start).then(|| &l[start..self.pos])
    }
}

fn parse_event(line: &[u8]) -> Option<(i64, u16, u16, i8)> {
    let mut it = Fields { line, pos: 0 };
    let t = parse_seconds_us(it.next()?)?;
    let x = u16::try_from(parse_uint(it.next()?)?).ok()?;
    let y = u16::try_from(parse_uint(it.next()?)?).ok()?;
    let p = match it.next()? {
        b"1" | b"+1" => 1,
        b"0" | b"-1" => -1,
        _ => return None,
    };
    if it.next().is_some() {
        return None;
    }
    Some((t, x, y, p))
}

impl<R: BufRead> EventReader for TextReader<R> {
    fn format(&self) -> &'static str {
        "text"
    }

    fn sensor(&self) -> Option<SensorSize> {
        self.sensor
    }

    fn read_chunk(&mut self, out: &mut EventStream, max: usize) -> Result<usize> {
        let mut n = 0;
        if max == 0 {
            return Ok(0);
        }
        if let Some((t, x, y, p)) = self.pending.take() {
            self.check(t, x, y, self.pending_line)?;
            out.t.push(t);
            out.x.push(x);
            out.y.push(y);
            out.p.push(p);
            n += 1;
            self.seen_data = true;
        }
        while n < max && self.next_line()? {
            let Some((t, x, y, p)) = parse_event(&self.line) else {
                let shown =
                    String::from_utf8_lossy(&self.line[..self.line.len().min(80)]).into_owned();
                return Err(EventsError::format(
                    &self.path,
                    format!(
                        "line {}: {:?} is not `t x y p`",
                        self.line_no,
                        shown.trim_end()
                    ),
                ));
            };
            self.check(t, x, y, self.line_no)?;
            out.t.push(t);
            out.x.push(x);
            out.y.push(y);
            out.p.push(p);
            n += 1;
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

/// Formats microseconds as decimal seconds with 6 decimals.
fn push_seconds(buf: &mut Vec<u8>, t_us: i64) {
    use std::io::Write as _;
    let sign = if t_us < 0 { "-" } else { "" };
    let a = t_us.unsigned_abs();
    let _ = write!(buf, "{sign}{}.{:06}", a / 1_000_000, a % 1_000_000);
}

/// Writes text events (`t x y p`, t in seconds with 6 decimals, p ∈ {0, 1}) to any writer; a
/// `width height` first line when the stream's sensor size is known.
pub fn write_text_to(w: &mut impl Write, events: &EventStream) -> std::io::Result<()> {
    use std::io::Write as _;
    if let Some(s) = events.sensor {
        writeln!(w, "{} {}", s.width, s.height)?;
    }
    let mut buf = Vec::with_capacity(1 << 16);
    for i in 0..events.len() {
        push_seconds(&mut buf, events.t[i]);
        let _ = writeln!(
            buf,
            " {} {} {}",
            events.x[i],
            events.y[i],
            u8::from(events.p[i] > 0)
        );
        if buf.len() > (1 << 16) - 64 {
            w.write_all(&buf)?;
            buf.clear();
        }
    }
    w.write_all(&buf)?;
    Ok(())
}

/// Writes a text event file (see [`write_text_to`]).
pub fn write_text(path: impl AsRef<Path>, events: &EventStream) -> Result<()> {
    let path = path.as_ref();
    let f = File::create(path).map_err(|e| EventsError::io(path, e))?;
    let mut w = BufWriter::with_capacity(1 << 20, f);
    write_text_to(&mut w, events).map_err(|e| EventsError::io(path, e))?;
    w.flush().map_err(|e| EventsError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_parse_exactly() {
        assert_eq!(parse_seconds_us(b"1.5"), Some(1_500_000));
        assert_eq!(parse_seconds_us(b"0.000001"), Some(1));
        assert_eq!(parse_seconds_us(b"0.0000015"), Some(2));
        assert_eq!(parse_seconds_us(b"12"), Some(12_000_000));
        assert_eq!(parse_seconds_us(b"1e-3"), Some(1000));
        assert_eq!(parse_seconds_us(b"-0.25"), Some(-250_000));
        assert_eq!(parse_seconds_us(b"abc"), None);
    }
}
