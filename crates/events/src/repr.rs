//! Dense tensor representations of event windows: the E-RAFT voxel grid, event-count frames and the
//! EventHPE-style binary time-slice frames. All outputs are planar f32 `(C, H, W)`, row-major.
//!
//! The voxel grid is the hot path (tens of millions of events per second): events are split into
//! fixed-size chunks whose partial grids are summed in chunk order, so the result is the same bit
//! for bit whatever the number of threads. Events outside the sensor are skipped, never panicking.

use rayon::prelude::*;

use crate::error::{EventsError, Result};
use crate::stream::{EventSlice, SensorSize};

/// Events per chunk of the parallel voxeliser (fixed, so results do not depend on thread count).
const VOXEL_CHUNK: usize = 1 << 20;

fn check_window(t0_us: i64, t1_us: i64) -> Result<()> {
    if t1_us <= t0_us {
        return Err(EventsError::arg(
            "t1_us",
            format!("window end {t1_us} us is not after its start {t0_us} us"),
        ));
    }
    Ok(())
}

fn voxel_accumulate(
    grid: &mut [f32],
    ev: &EventSlice<'_>,
    sensor: SensorSize,
    bins: usize,
    t0: i64,
    scale: f32,
) {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let plane = w * h;
    let last = (bins - 1) as f32;
    for i in 0..ev.len() {
        let (x, y) = (ev.x[i] as usize, ev.y[i] as usize);
        if x >= w || y >= h {
            continue;
        }
        let tn = ((ev.t[i] - t0) as f32 * scale).clamp(0.0, last);
        let b0 = tn as usize;
        let frac = tn - b0 as f32;
        let v = if ev.p[i] > 0 { 1.0f32 } else { -1.0 };
        let idx = b0 * plane + y * w + x;
        grid[idx] += v * (1.0 - frac);
        if b0 + 1 < bins {
            grid[idx + plane] += v * frac;
        }
    }
}

/// E-RAFT voxel grid `(bins, H, W)`: each event adds `2p−1 = ±1` to the two nearest bins of
/// `t* = (bins−1)(t−t0)/(t1−t0)`, weighted `1−|b−t*|` (bilinear in time). Events before `t0`/after
/// `t1` clamp to the end bins. With `normalize`, the non-zero voxels are standardised to mean 0 and
/// standard deviation 1 (as E-RAFT does), zeros stay zero.
pub fn voxel_grid(
    events: &EventSlice<'_>,
    sensor: SensorSize,
    bins: usize,
    t0_us: i64,
    t1_us: i64,
    normalize: bool,
) -> Result<Vec<f32>> {
    if bins == 0 {
        return Err(EventsError::arg("bins", "must be at least 1".to_string()));
    }
    check_window(t0_us, t1_us)?;
    let plane = sensor.pixels();
    let scale = if bins > 1 {
        (bins - 1) as f32 / (t1_us - t0_us) as f32
    } else {
        0.0
    };
    let mut grid = vec![0.0f32; bins * plane];
    if events.len() <= VOXEL_CHUNK {
        voxel_accumulate(&mut grid, events, sensor, bins, t0_us, scale);
    } else {
        let starts: Vec<usize> = (0..events.len()).step_by(VOXEL_CHUNK).collect();
        // Two chunks at a time keep memory at 2 extra grids; partial grids are added in chunk order.
        for pair in starts.chunks(2) {
            let partials: Vec<Vec<f32>> = pair
                .par_iter()
                .map(|&s| {
                    let e = (s + VOXEL_CHUNK).min(events.len());
                    let mut g = vec![0.0f32; bins * plane];
                    voxel_accumulate(&mut g, &events.range(s..e), sensor, bins, t0_us, scale);
                    g
                })
                .collect();
            for p in partials {
                grid.par_iter_mut()
                    .zip(p.par_iter())
                    .for_each(|(a, b)| *a += b);
            }
        }
    }
    if normalize {
        normalize_nonzero(&mut grid);
    }
    Ok(grid)
}

/// Standardises the non-zero entries to mean 0 / standard deviation 1 (f64 statistics).
pub fn normalize_nonzero(grid: &mut [f32]) {
    let (mut n, mut s, mut s2) = (0u64, 0.0f64, 0.0f64);
    for &v in grid.iter() {
        if v != 0.0 {
            n += 1;
            s += v as f64;
            s2 += v as f64 * v as f64;
        }
    }
    if n == 0 {
        return;
    }
    let mean = s / n as f64;
    let var = (s2 / n as f64 - mean * mean).max(0.0);
    let std = var.sqrt();
    for v in grid.iter_mut() {
        if *v != 0.0 {
            *v = if std > 0.0 {
                ((*v as f64 - mean) / std) as f32
            } else {
                (*v as f64 - mean) as f32
            };
        }
    }
}

/// How [`count_frame`] counts events per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CountMode {
    /// One channel: (#positive − #negative).
    Signed,
    /// One channel: #events regardless of polarity.
    Unsigned,
    /// Two channels: #positive, then #negative.
    TwoChannel,
}

/// Event-count frame `(C, H, W)` with C = 1 or 2 (see [`CountMode`]); events outside the sensor
/// are skipped.
pub fn count_frame(events: &EventSlice<'_>, sensor: SensorSize, mode: CountMode) -> Vec<f32> {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let plane = w * h;
    let channels = if mode == CountMode::TwoChannel { 2 } else { 1 };
    let mut out = vec![0.0f32; channels * plane];
    for i in 0..events.len() {
        let (x, y) = (events.x[i] as usize, events.y[i] as usize);
        if x >= w || y >= h {
            continue;
        }
        let idx = y * w + x;
        let pos = events.p[i] > 0;
        match mode {
            CountMode::Signed => out[idx] += if pos { 1.0 } else { -1.0 },
            CountMode::Unsigned => out[idx] += 1.0,
            CountMode::TwoChannel => out[if pos { idx } else { plane + idx }] += 1.0,
        }
    }
    out
}

/// EventHPE-style binary time-slice frames `(slices, H, W)`: the window `[t0, t1)` is cut into
/// `slices` equal parts and a pixel of slice k is 1 when at least one event (any polarity) fell in
/// it, else 0. Events outside the window or the sensor are skipped.
pub fn time_slice_frames(
    events: &EventSlice<'_>,
    sensor: SensorSize,
    slices: usize,
    t0_us: i64,
    t1_us: i64,
) -> Result<Vec<f32>> {
    if slices == 0 {
        return Err(EventsError::arg("slices", "must be at least 1".to_string()));
    }
    check_window(t0_us, t1_us)?;
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let plane = w * h;
    let mut out = vec![0.0f32; slices * plane];
    let span = (t1_us - t0_us) as i128;
    for i in 0..events.len() {
        let (x, y, t) = (events.x[i] as usize, events.y[i] as usize, events.t[i]);
        if x >= w || y >= h || t < t0_us || t >= t1_us {
            continue;
        }
        let k = ((t - t0_us) as i128 * slices as i128 / span) as usize;
        out[k.min(slices - 1) * plane + y * w + x] = 1.0;
    }
    Ok(out)
}
