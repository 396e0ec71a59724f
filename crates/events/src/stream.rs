//! Event streams as struct-of-arrays: `t` (i64 microseconds), `x`, `y` (u16 pixels, column/row with
//! row 0 at the top, DESIGN.md §3) and `p` (i8, +1 brighter / -1 darker).
//!
//! The container is the exchange type between readers, writers, the simulator and the
//! representations. It never reorders events on its own: sorting and validation are explicit calls,
//! so a reader can report non-monotonic timestamps instead of hiding them.

use std::ops::Range;

use crate::error::{EventsError, Result};

/// Sensor size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SensorSize {
    /// Number of columns (pixels); valid x are `0..width`.
    pub width: u32,
    /// Number of rows (pixels); valid y are `0..height`.
    pub height: u32,
}

impl SensorSize {
    /// A sensor of `width` x `height` pixels.
    pub const fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// One event: timestamp in microseconds, pixel column `x`, pixel row `y`, polarity ±1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Event {
    /// Timestamp (microseconds, any origin).
    pub t: i64,
    /// Column (pixels, 0 = left).
    pub x: u16,
    /// Row (pixels, 0 = top).
    pub y: u16,
    /// Polarity: +1 for a log-brightness increase, -1 for a decrease.
    pub p: i8,
}

/// A borrowed window of an [`EventStream`] (same layout, no copy).
#[derive(Clone, Copy, Debug)]
pub struct EventSlice<'a> {
    /// Timestamps (microseconds).
    pub t: &'a [i64],
    /// Columns (pixels).
    pub x: &'a [u16],
    /// Rows (pixels).
    pub y: &'a [u16],
    /// Polarities (±1).
    pub p: &'a [i8],
}

impl<'a> EventSlice<'a> {
    /// Number of events.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Event `i` (panics when out of range, like slice indexing).
    pub fn get(&self, i: usize) -> Event {
        Event {
            t: self.t[i],
            x: self.x[i],
            y: self.y[i],
            p: self.p[i],
        }
    }

    /// Iterator over the events.
    pub fn iter(&self) -> impl Iterator<Item = Event> + 'a {
        let s = *self;
        (0..s.len()).map(move |i| s.get(i))
    }

    /// Index range of the events with `t0_us <= t < t1_us`, found by binary search. Requires
    /// time-sorted events (see [`EventStream::validate`]).
    pub fn time_range(&self, t0_us: i64, t1_us: i64) -> Range<usize> {
        let start = self.t.partition_point(|&t| t < t0_us);
        let end = self.t.partition_point(|&t| t < t1_us).max(start);
        start..end
    }

    /// The sub-slice of events with `t0_us <= t < t1_us` (binary search; requires sorted times).
    pub fn window(&self, t0_us: i64, t1_us: i64) -> EventSlice<'a> {
        self.range(self.time_range(t0_us, t1_us))
    }

    /// The sub-slice of events at indices `r`.
    pub fn range(&self, r: Range<usize>) -> EventSlice<'a> {
        EventSlice {
            t: &self.t[r.clone()],
            x: &self.x[r.clone()],
            y: &self.y[r.clone()],
            p: &self.p[r],
        }
    }

    /// Number of events with positive polarity.
    pub fn positive_count(&self) -> usize {
        self.p.iter().filter(|&&p| p > 0).count()
    }
}

/// A stream of events stored as struct-of-arrays, with the sensor size when known.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EventStream {
    /// Timestamps (microseconds).
    pub t: Vec<i64>,
    /// Columns (pixels, 0 = left).
    pub x: Vec<u16>,
    /// Rows (pixels, 0 = top).
    pub y: Vec<u16>,
    /// Polarities (+1 / -1).
    pub p: Vec<i8>,
    /// Sensor size, when the source stated it.
    pub sensor: Option<SensorSize>,
}

impl EventStream {
    /// An empty stream without a sensor size.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty stream with room for `n` events (callers must bound `n`; readers never pass a
    /// header value here unchecked).
    pub fn with_capacity(n: usize) -> Self {
        Self {
            t: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
            sensor: None,
        }
    }

    /// A stream from events.
    pub fn from_events(
        events: impl IntoIterator<Item = Event>,
        sensor: Option<SensorSize>,
    ) -> Self {
        let mut s = Self::new();
        s.sensor = sensor;
        for e in events {
            s.push(e);
        }
        s
    }

    /// Number of events.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Appends one event.
    #[inline]
    pub fn push(&mut self, e: Event) {
        self.t.push(e.t);
        self.x.push(e.x);
        self.y.push(e.y);
        self.p.push(e.p);
    }

    /// Appends all events of `other` (the sensor size is kept when already set).
    pub fn extend_from(&mut self, other: &EventSlice<'_>) {
        self.t.extend_from_slice(other.t);
        self.x.extend_from_slice(other.x);
        self.y.extend_from_slice(other.y);
        self.p.extend_from_slice(other.p);
    }

    /// Tries to reserve room for `additional` more events in every column; false if the allocator
    /// refuses (columns reserved before the refusal keep their room). For size estimates, which
    /// must not abort the process.
    pub fn try_reserve(&mut self, additional: usize) -> bool {
        self.t.try_reserve_exact(additional).is_ok()
            && self.x.try_reserve_exact(additional).is_ok()
            && self.y.try_reserve_exact(additional).is_ok()
            && self.p.try_reserve_exact(additional).is_ok()
    }

    /// Keeps the first `len` events (no effect when there are fewer).
    pub fn truncate(&mut self, len: usize) {
        self.t.truncate(len);
        self.x.truncate(len);
        self.y.truncate(len);
        self.p.truncate(len);
    }

    /// Removes all events, keeping the allocation and the sensor size.
    pub fn clear(&mut self) {
        self.t.clear();
        self.x.clear();
        self.y.clear();
        self.p.clear();
    }

    /// Event `i` (panics when out of range).
    pub fn get(&self, i: usize) -> Event {
        self.as_slice().get(i)
    }

    /// A borrowed view of all events.
    pub fn as_slice(&self) -> EventSlice<'_> {
        EventSlice {
            t: &self.t,
            x: &self.x,
            y: &self.y,
            p: &self.p,
        }
    }

    /// Iterator over the events.
    pub fn iter(&self) -> impl Iterator<Item = Event> + '_ {
        self.as_slice().iter()
    }

    /// Events with `t0_us <= t < t1_us` (binary search; requires time-sorted events).
    pub fn window(&self, t0_us: i64, t1_us: i64) -> EventSlice<'_> {
        self.as_slice().window(t0_us, t1_us)
    }

    /// Index range of events with `t0_us <= t < t1_us` (binary search; requires sorted times).
    pub fn time_range(&self, t0_us: i64, t1_us: i64) -> Range<usize> {
        self.as_slice().time_range(t0_us, t1_us)
    }

    /// Number of events with positive polarity.
    pub fn positive_count(&self) -> usize {
        self.as_slice().positive_count()
    }

    /// Checks that timestamps never decrease, that polarities are ±1 and, when `sensor` (or else the
    /// stream's own sensor size) is known, that every event lies inside it. Returns the first
    /// violation.
    pub fn validate(&self, sensor: Option<SensorSize>) -> Result<()> {
        check_slice(&self.as_slice(), sensor.or(self.sensor), 0)
    }

    /// True when timestamps never decrease.
    pub fn is_time_sorted(&self) -> bool {
        self.t.windows(2).all(|w| w[0] <= w[1])
    }

    /// Stable sort by timestamp (events with equal timestamps keep their order).
    pub fn sort_by_time(&mut self) {
        if self.is_time_sorted() {
            return;
        }
        let mut idx: Vec<u32> = (0..self.len() as u32).collect();
        idx.sort_by_key(|&i| self.t[i as usize]);
        self.permute(&idx);
    }

    /// Stable sort by (t, y, x): the canonical order of the simulator's output.
    pub fn sort_by_time_row_col(&mut self) {
        let mut idx: Vec<u32> = (0..self.len() as u32).collect();
        idx.sort_by_key(|&i| {
            let i = i as usize;
            (self.t[i], self.y[i], self.x[i])
        });
        self.permute(&idx);
    }

    fn permute(&mut self, idx: &[u32]) {
        self.t = idx.iter().map(|&i| self.t[i as usize]).collect();
        self.x = idx.iter().map(|&i| self.x[i as usize]).collect();
        self.y = idx.iter().map(|&i| self.y[i as usize]).collect();
        self.p = idx.iter().map(|&i| self.p[i as usize]).collect();
    }

    /// The smallest sensor that contains every event (`None` when empty).
    pub fn bounding_sensor(&self) -> Option<SensorSize> {
        let w = self.x.iter().max()?;
        let h = self.y.iter().max()?;
        Some(SensorSize::new(*w as u32 + 1, *h as u32 + 1))
    }
}

/// Validates a slice whose first event has global index `offset` (monotonic time, ±1 polarity,
/// inside `sensor` when given).
pub(crate) fn check_slice(
    s: &EventSlice<'_>,
    sensor: Option<SensorSize>,
    offset: usize,
) -> Result<()> {
    for i in 1..s.len() {
        if s.t[i] < s.t[i - 1] {
            return Err(EventsError::NonMonotonic {
                index: offset + i,
                previous_us: s.t[i - 1],
                t_us: s.t[i],
            });
        }
    }
    for (i, &p) in s.p.iter().enumerate() {
        if p != 1 && p != -1 {
            return Err(EventsError::BadPolarity {
                index: offset + i,
                p,
            });
        }
    }
    if let Some(sz) = sensor {
        for i in 0..s.len() {
            if s.x[i] as u32 >= sz.width || s.y[i] as u32 >= sz.height {
                return Err(EventsError::OutsideSensor {
                    index: offset + i,
                    x: s.x[i],
                    y: s.y[i],
                    width: sz.width,
                    height: sz.height,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(t: i64, x: u16, y: u16, p: i8) -> Event {
        Event { t, x, y, p }
    }

    #[test]
    fn window_uses_half_open_interval() {
        let s = EventStream::from_events(
            [
                ev(0, 0, 0, 1),
                ev(10, 1, 0, 1),
                ev(10, 2, 0, -1),
                ev(20, 0, 1, 1),
                ev(30, 0, 0, 1),
            ],
            None,
        );
        assert_eq!(s.time_range(10, 30), 1..4);
        assert_eq!(s.window(10, 30).len(), 3);
        assert_eq!(s.time_range(31, 100), 5..5);
        assert_eq!(s.time_range(20, 10), 3..3);
        assert_eq!(s.window(-5, 1).get(0), ev(0, 0, 0, 1));
    }

    #[test]
    fn validate_reports_the_first_violation() {
        let mut s =
            EventStream::from_events([ev(5, 0, 0, 1), ev(3, 1, 0, 1), ev(4, 9, 0, 1)], None);
        match s.validate(None) {
            Err(EventsError::NonMonotonic {
                index: 1,
                previous_us: 5,
                t_us: 3,
            }) => {}
            other => panic!("unexpected {other:?}"),
        }
        s.sort_by_time();
        assert_eq!(s.t, vec![3, 4, 5]);
        assert_eq!(s.x, vec![1, 9, 0]);
        match s.validate(Some(SensorSize::new(4, 4))) {
            Err(EventsError::OutsideSensor { index: 1, x: 9, .. }) => {}
            other => panic!("unexpected {other:?}"),
        }
        s.p[2] = 0;
        assert!(matches!(
            s.validate(None),
            Err(EventsError::BadPolarity { index: 2, p: 0 })
        ));
    }
}
