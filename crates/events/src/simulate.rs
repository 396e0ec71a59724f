//! ESIM-style event simulator: turns a sequence of timestamped intensity frames into events.
//!
//! Model (Rebecq et al., "ESIM", CoRL 2018): per pixel the log intensity `L = log(I + eps)` is
//! linearly interpolated between consecutive frames; an event of polarity ±1 is emitted at every
//! crossing of `reference ± k·C` inside `(L_prev, L_next]`, at the linearly interpolated time, and the
//! reference moves to the last crossing. Each pixel has its own thresholds `C± ~ N(C±, σ)` clamped to
//! at least `min_threshold`; events closer than the refractory period to the pixel's previous event
//! are dropped (the reference still moves, as in ESIM); optional shot noise (background activity)
//! adds Poisson events of random polarity, and optional hot pixels fire at a fixed rate whatever
//! the scene does (a leaky pixel of a real sensor: one polarity each, a random phase).
//!
//! Determinism: every random draw comes from ChaCha8 streams derived from the seed (thresholds from
//! stream 0, row `r` from stream `r + 1`), rows run in parallel with rayon, and the output is merged
//! row by row and stably sorted by (t, y, x): the same seed gives the same events, bit for bit,
//! whatever the thread count. The simulator never reads files and never resamples frames.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Poisson};
use rayon::prelude::*;

use crate::error::{EventsError, Result};
use crate::stream::{Event, EventStream, SensorSize};

/// Simulator parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EsimConfig {
    /// Mean positive contrast threshold C+ (log-intensity units).
    pub c_pos: f32,
    /// Mean negative contrast threshold C- (log-intensity units, positive number).
    pub c_neg: f32,
    /// Standard deviation σ of the per-pixel thresholds (log-intensity units; 0 = no noise).
    pub sigma: f32,
    /// Lower clamp of every per-pixel threshold (log-intensity units).
    pub min_threshold: f32,
    /// `eps` in `L = log(I + eps)`, with `I` linear intensity in [0, 1] (negative values clamp to 0).
    pub log_eps: f32,
    /// Refractory period (microseconds): an event closer than this to the pixel's previous event is
    /// dropped. 0 disables it.
    pub refractory_us: i64,
    /// Shot-noise (background-activity) rate per pixel (events per second, random polarity,
    /// uniform time; not subject to the refractory period). 0 disables it.
    pub shot_noise_hz: f64,
    /// Fraction of the pixels that are hot, in [0, 1): chosen at random (their own ChaCha8 stream),
    /// each fires events of one polarity (random, ON or OFF) every `1 / hot_pixel_rate_hz` seconds
    /// from a random phase, whatever the scene does. 0 disables them (and draws nothing).
    pub hot_pixel_fraction: f64,
    /// Event rate of every hot pixel (events per second, > 0 when `hot_pixel_fraction` > 0).
    pub hot_pixel_rate_hz: f64,
    /// Seed of every random draw.
    pub seed: u64,
}

impl Default for EsimConfig {
    /// C± = 0.2, σ = 0.03, clamp 0.01, eps = 1e-3, no refractory period, no shot noise, no hot
    /// pixels (200 Hz when some are asked for), seed 0.
    fn default() -> Self {
        Self {
            c_pos: 0.2,
            c_neg: 0.2,
            sigma: 0.03,
            min_threshold: 0.01,
            log_eps: 1e-3,
            refractory_us: 0,
            shot_noise_hz: 0.0,
            hot_pixel_fraction: 0.0,
            hot_pixel_rate_hz: 200.0,
            seed: 0,
        }
    }
}

/// Rec. 709 luma of a planar linear RGB image `(3, H, W)`: the grey frame the simulator expects.
pub fn grey_from_rgb(rgb: &[f32], width: usize, height: usize) -> Result<Vec<f32>> {
    let n = width * height;
    if rgb.len() != 3 * n {
        return Err(EventsError::arg(
            "rgb",
            format!("length {} is not 3*{width}*{height}", rgb.len()),
        ));
    }
    Ok((0..n)
        .map(|i| 0.2126 * rgb[i] + 0.7152 * rgb[n + i] + 0.0722 * rgb[2 * n + i])
        .collect())
}

/// Per-row mutable state, processed by one rayon task.
struct RowState {
    reference: Vec<f32>,
    last_log: Vec<f32>,
    last_event_us: Vec<i64>,
    rng: ChaCha8Rng,
    /// The row's hot pixels: (column, polarity, first firing time in µs), by column.
    hot: Vec<HotPixel>,
}

/// A pixel that fires at a fixed rate whatever the scene does.
#[derive(Clone, Copy, Debug)]
struct HotPixel {
    x: u16,
    polarity: i8,
    /// Phase of its firing times, in [0, period) microseconds.
    phase_us: f64,
}

/// ChaCha8 stream of the hot-pixel draws (the thresholds use stream 0, row r stream r + 1 ≤ 65536).
const HOT_PIXEL_STREAM: u64 = 1 << 32;

/// Stateful ESIM simulator: feed frames in time order with [`EventSimulator::add_frame`].
pub struct EventSimulator {
    config: EsimConfig,
    width: usize,
    height: usize,
    c_pos: Vec<f32>,
    c_neg: Vec<f32>,
    rows: Vec<RowState>,
    last_t_us: Option<i64>,
}

impl EventSimulator {
    /// A simulator for `width` x `height` frames. Draws the per-pixel thresholds.
    pub fn new(config: EsimConfig, width: usize, height: usize) -> Result<Self> {
        if width == 0
            || height == 0
            || width > u16::MAX as usize + 1
            || height > u16::MAX as usize + 1
        {
            return Err(EventsError::arg(
                "width/height",
                format!(
                    "{width}x{height} is empty or exceeds the 65536x65536 event coordinate range"
                ),
            ));
        }
        for (name, c) in [("c_pos", config.c_pos), ("c_neg", config.c_neg)] {
            if !(c.is_finite() && c > 0.0) {
                return Err(EventsError::arg(
                    name,
                    format!("threshold {c} must be finite and > 0"),
                ));
            }
        }
        if !(config.min_threshold.is_finite() && config.min_threshold > 0.0) {
            return Err(EventsError::arg(
                "min_threshold",
                format!("{} must be finite and > 0", config.min_threshold),
            ));
        }
        if !(config.sigma.is_finite() && config.sigma >= 0.0) {
            return Err(EventsError::arg(
                "sigma",
                format!("{} must be finite and >= 0", config.sigma),
            ));
        }
        if !(config.log_eps.is_finite() && config.log_eps > 0.0) {
            return Err(EventsError::arg(
                "log_eps",
                format!("{} must be finite and > 0", config.log_eps),
            ));
        }
        if !(config.shot_noise_hz.is_finite() && config.shot_noise_hz >= 0.0) {
            return Err(EventsError::arg(
                "shot_noise_hz",
                format!("{} must be finite and >= 0", config.shot_noise_hz),
            ));
        }
        if !(config.hot_pixel_fraction.is_finite()
            && (0.0..1.0).contains(&config.hot_pixel_fraction))
        {
            return Err(EventsError::arg(
                "hot_pixel_fraction",
                format!("{} must be in [0, 1)", config.hot_pixel_fraction),
            ));
        }
        if config.hot_pixel_fraction > 0.0
            && !(config.hot_pixel_rate_hz.is_finite()
                && config.hot_pixel_rate_hz > 0.0
                && config.hot_pixel_rate_hz <= 1e6)
        {
            return Err(EventsError::arg(
                "hot_pixel_rate_hz",
                format!("{} must be in (0, 1e6]", config.hot_pixel_rate_hz),
            ));
        }
        if config.refractory_us < 0 {
            return Err(EventsError::arg(
                "refractory_us",
                format!("{} must be >= 0", config.refractory_us),
            ));
        }
        let n = width * height;
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        rng.set_stream(0);
        let mut draw = |mean: f32| -> Result<Vec<f32>> {
            let normal = Normal::new(mean, config.sigma)
                .map_err(|e| EventsError::arg("sigma", format!("{}: {e}", config.sigma)))?;
            Ok((0..n)
                .map(|_| {
                    let c = if config.sigma > 0.0 {
                        normal.sample(&mut rng)
                    } else {
                        mean
                    };
                    c.max(config.min_threshold)
                })
                .collect())
        };
        let c_pos = draw(config.c_pos)?;
        let c_neg = draw(config.c_neg)?;
        let mut hot_by_row = hot_pixels(&config, width, height);
        let rows = (0..height)
            .map(|r| {
                let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
                rng.set_stream(r as u64 + 1);
                RowState {
                    reference: vec![0.0; width],
                    last_log: vec![0.0; width],
                    last_event_us: vec![i64::MIN; width],
                    rng,
                    hot: std::mem::take(&mut hot_by_row[r]),
                }
            })
            .collect();
        Ok(Self {
            config,
            width,
            height,
            c_pos,
            c_neg,
            rows,
            last_t_us: None,
        })
    }

    /// Sensor size of the simulated camera.
    pub fn sensor(&self) -> SensorSize {
        SensorSize::new(self.width as u32, self.height as u32)
    }

    /// Per-pixel positive thresholds (row-major, log-intensity units).
    pub fn thresholds_pos(&self) -> &[f32] {
        &self.c_pos
    }

    /// Per-pixel negative thresholds (row-major, log-intensity units, positive numbers).
    pub fn thresholds_neg(&self) -> &[f32] {
        &self.c_neg
    }

    /// Adds a grey linear-intensity frame (`H*W`, row-major) taken at `t_us` microseconds and returns
    /// the events between the previous frame and this one, sorted by (t, y, x). The first frame only
    /// initialises the references and returns no events. Times must strictly increase.
    pub fn add_frame(&mut self, t_us: i64, frame: &[f32]) -> Result<EventStream> {
        let (w, h) = (self.width, self.height);
        if frame.len() != w * h {
            return Err(EventsError::arg(
                "frame",
                format!("length {} is not {w}*{h}", frame.len()),
            ));
        }
        if let Some(i) = frame.iter().position(|v| !v.is_finite()) {
            return Err(EventsError::arg(
                "frame",
                format!("pixel {i} (x={}, y={}) is {}", i % w, i / w, frame[i]),
            ));
        }
        let eps = self.config.log_eps;
        let log_of = |v: f32| (v.max(0.0) + eps).ln();
        let Some(t_prev) = self.last_t_us else {
            for (r, row) in self.rows.iter_mut().enumerate() {
                for x in 0..w {
                    let l = log_of(frame[r * w + x]);
                    row.reference[x] = l;
                    row.last_log[x] = l;
                }
            }
            self.last_t_us = Some(t_us);
            let mut s = EventStream::new();
            s.sensor = Some(self.sensor());
            return Ok(s);
        };
        if t_us <= t_prev {
            return Err(EventsError::arg(
                "t_us",
                format!("frame time {t_us} us is not after the previous frame time {t_prev} us"),
            ));
        }
        let cfg = self.config;
        let dt = (t_us - t_prev) as f64;
        let (c_pos, c_neg) = (&self.c_pos, &self.c_neg);
        let per_row: Vec<Vec<Event>> = self
            .rows
            .par_iter_mut()
            .enumerate()
            .map(|(r, row)| {
                let mut out = Vec::new();
                for x in 0..w {
                    let i = r * w + x;
                    let l0 = row.last_log[x];
                    let l1 = log_of(frame[i]);
                    row.last_log[x] = l1;
                    if l1 == l0 {
                        continue;
                    }
                    let (pol, c) = if l1 > l0 {
                        (1i8, c_pos[i])
                    } else {
                        (-1i8, c_neg[i])
                    };
                    let step = pol as f32 * c;
                    let mut cross = row.reference[x];
                    loop {
                        cross += step;
                        let inside = if pol > 0 {
                            cross > l0 && cross <= l1
                        } else {
                            cross < l0 && cross >= l1
                        };
                        if !inside {
                            break;
                        }
                        let frac = (cross as f64 - l0 as f64) / (l1 as f64 - l0 as f64);
                        let t = t_prev + (frac * dt).round() as i64;
                        if row.last_event_us[x] == i64::MIN
                            || t - row.last_event_us[x] >= cfg.refractory_us
                        {
                            out.push(Event {
                                t,
                                x: x as u16,
                                y: r as u16,
                                p: pol,
                            });
                            row.last_event_us[x] = t;
                        }
                        row.reference[x] = cross;
                    }
                }
                for hot in &row.hot {
                    push_hot_events(hot, r as u16, t_prev, t_us, cfg.hot_pixel_rate_hz, &mut out);
                }
                if cfg.shot_noise_hz > 0.0 {
                    let lambda = cfg.shot_noise_hz * w as f64 * dt * 1e-6;
                    if let Ok(poisson) = Poisson::new(lambda) {
                        let count: f64 = poisson.sample(&mut row.rng);
                        for _ in 0..count as u64 {
                            let x = row.rng.gen_range(0..w);
                            let t = t_prev + 1 + row.rng.gen_range(0..(t_us - t_prev));
                            let p = if row.rng.gen::<bool>() { 1 } else { -1 };
                            out.push(Event {
                                t,
                                x: x as u16,
                                y: r as u16,
                                p,
                            });
                        }
                    }
                }
                out
            })
            .collect();
        self.last_t_us = Some(t_us);
        let total = per_row.iter().map(Vec::len).sum();
        let mut s = EventStream::with_capacity(total);
        s.sensor = Some(self.sensor());
        for row in per_row {
            for e in row {
                s.push(e);
            }
        }
        s.sort_by_time_row_col();
        Ok(s)
    }
}

/// The hot pixels of a sensor, per row: `round(fraction · W · H)` distinct pixels drawn from
/// their own stream, each with a random polarity and phase. Empty rows without hot pixels.
fn hot_pixels(config: &EsimConfig, width: usize, height: usize) -> Vec<Vec<HotPixel>> {
    let mut rows = vec![Vec::new(); height];
    let n = width * height;
    let count = ((config.hot_pixel_fraction * n as f64).round() as usize).min(n);
    if count == 0 {
        return rows;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    rng.set_stream(HOT_PIXEL_STREAM);
    let period_us = 1e6 / config.hot_pixel_rate_hz;
    for i in rand::seq::index::sample(&mut rng, n, count).into_vec() {
        let polarity = if rng.gen::<bool>() { 1 } else { -1 };
        let phase_us = rng.gen::<f64>() * period_us;
        rows[i / width].push(HotPixel {
            x: (i % width) as u16,
            polarity,
            phase_us,
        });
    }
    for row in &mut rows {
        row.sort_by_key(|h| h.x);
    }
    rows
}

/// Appends a hot pixel's events in `(t_prev, t_us]`: its firing times `phase + k / rate` (µs,
/// rounded), so that consecutive intervals never repeat or miss one.
fn push_hot_events(
    hot: &HotPixel,
    y: u16,
    t_prev: i64,
    t_us: i64,
    rate_hz: f64,
    out: &mut Vec<Event>,
) {
    let period_us = 1e6 / rate_hz;
    let firing = |k: f64| (hot.phase_us + k * period_us).round() as i64;
    // The first k whose firing time is after t_prev (k from the real quotient, then corrected
    // for the rounding of the times).
    let mut k = ((t_prev as f64 - hot.phase_us) / period_us)
        .floor()
        .max(0.0);
    while firing(k) <= t_prev {
        k += 1.0;
    }
    while k > 0.0 && firing(k - 1.0) > t_prev {
        k -= 1.0;
    }
    while firing(k) <= t_us {
        out.push(Event {
            t: firing(k),
            x: hot.x,
            y,
            p: hot.polarity,
        });
        k += 1.0;
    }
}

/// Simulates a whole sequence of grey linear-intensity frames (`frames[k]` is `H*W` row-major,
/// taken at `times_us[k]`) and returns all events sorted by (t, y, x), sensor size set.
pub fn simulate_sequence(
    config: EsimConfig,
    width: usize,
    height: usize,
    times_us: &[i64],
    frames: &[&[f32]],
) -> Result<EventStream> {
    if times_us.len() != frames.len() {
        return Err(EventsError::arg(
            "times_us",
            format!("{} times for {} frames", times_us.len(), frames.len()),
        ));
    }
    let mut sim = EventSimulator::new(config, width, height)?;
    let mut all = EventStream::new();
    all.sensor = Some(sim.sensor());
    for (&t, f) in times_us.iter().zip(frames) {
        let s = sim.add_frame(t, f)?;
        all.extend_from(&s.as_slice());
    }
    Ok(all)
}
