//! The word decoders of the Prophesee formats (`.dat` CD events, EVT 2.0, EVT 3.0): each fills a
//! fixed [`Block`] of events and reports the first bad word of its buffer.

use super::*;

/// The first bad word of a buffer: its index in the buffer and what is wrong.
pub(super) struct BadWord {
    pub(super) index: usize,
    pub(super) message: String,
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
    /// A `.dat` polarity nibble other than 0 or 1.
    Polarity(u32),
    /// A `.dat` event earlier than the one before it (µs), not a wrap of the counter.
    TimeBack { from: i64, to: i64 },
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
            Self::Polarity(p) => format!(
                "{format} event {word}: polarity {p} is not 0 or 1 (not a .dat CD stream, or a \
                 corrupt one; --lenient skips bad events)"
            ),
            Self::TimeBack { from, to } => format!(
                "{format} event {word} goes back {} us in time (events must be in time order)",
                from - to
            ),
            Self::Backwards { from, to, step_us } => format!(
                "{format} word {word}: TIME_HIGH {to:#x} after {from:#x} sends time back by {} us \
                 (a drop is a wrap of the counter only from its top to its bottom)",
                (from - to) * step_us
            ),
        }
    }
}

/// Events per [`Block`].
const BLOCK: usize = 1024;
/// Most events one word can add (an EVT 3.0 VECT_12 word).
const MAX_EVENTS_PER_WORD: usize = 12;

/// A fixed block of decoded events on the stack, appended to the output columns when full: the
/// decoders' inner loops then store into plain arrays instead of growing four `Vec`s per event.
pub(super) struct Block {
    t: [i64; BLOCK],
    x: [u16; BLOCK],
    y: [u16; BLOCK],
    p: [i8; BLOCK],
    len: usize,
}

impl Block {
    pub(super) fn new() -> Self {
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
    pub(super) fn flush(&mut self, out: &mut EventStream) {
        out.t.extend_from_slice(&self.t[..self.len]);
        out.x.extend_from_slice(&self.x[..self.len]);
        out.y.extend_from_slice(&self.y[..self.len]);
        out.p.extend_from_slice(&self.p[..self.len]);
        self.len = 0;
    }
}

impl<R: BufRead> PropheseeReader<R> {
    /// Decodes `.dat` CD events (u32 µs, then x in bits 0–13, y in 14–27, polarity in 28–31);
    /// returns the first bad one (strict) or `None`. A polarity other than 0 or 1 is bad, and so
    /// is time going back, except the wrap of the 32-bit counter (a drop of at least 2³² − 2 s
    /// worth of microseconds' slack, from its top to its bottom).
    pub(super) fn decode_dat(
        &mut self,
        block: &mut Block,
        out: &mut EventStream,
    ) -> Option<BadWord> {
        const LOOP: i64 = 1 << 32;
        const WRAP_SLACK_US: i64 = 2_000_000;
        let (mut last, mut seen, mut wraps) = (self.dat_last, self.dat_seen, self.dat_wraps);
        let mut bad = None;
        for (i, c) in self.buf.chunks_exact(8).enumerate() {
            block.make_room(out);
            let raw_t = i64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
            let d = u32::from_le_bytes([c[4], c[5], c[6], c[7]]);
            let pol = (d >> 28) & 0xF;
            let current = last - wraps * LOOP;
            let problem = if pol > 1 {
                Some(Problem::Polarity(pol))
            } else if seen && raw_t < current {
                if current - raw_t >= LOOP - WRAP_SLACK_US {
                    wraps += 1;
                    None
                } else {
                    Some(Problem::TimeBack {
                        from: current,
                        to: raw_t,
                    })
                }
            } else {
                None
            };
            match problem {
                None => {
                    let t = raw_t + wraps * LOOP;
                    (last, seen) = (t, true);
                    block.put(
                        t,
                        (d & 0x3FFF) as u16,
                        ((d >> 14) & 0x3FFF) as u16,
                        if pol != 0 { 1 } else { -1 },
                        true,
                    );
                }
                Some(_) if self.lenient => self.skipped += 1,
                Some(p) => {
                    bad = Some(BadWord {
                        index: i,
                        message: p.describe(
                            &format!("{d:#010x} at t = {raw_t} us"),
                            ".dat",
                            &self.bounds(),
                        ),
                    });
                    break;
                }
            }
        }
        (self.dat_last, self.dat_seen, self.dat_wraps) = (last, seen, wraps);
        bad
    }

    /// Decodes EVT 2.0 words; returns the first bad word (strict) or `None`.
    pub(super) fn decode_evt2(
        &mut self,
        block: &mut Block,
        out: &mut EventStream,
    ) -> Option<BadWord> {
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
    pub(super) fn decode_evt3(
        &mut self,
        block: &mut Block,
        out: &mut EventStream,
    ) -> Option<BadWord> {
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
