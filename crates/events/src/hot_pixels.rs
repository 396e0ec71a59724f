//! Hot pixels: pixels of a real sensor that fire at a high rate whatever the scene does (a leaky
//! photoreceptor or a reset switch). Found the way event-camera software does — a pixel whose event
//! count over a recording towers over its neighbours' — and removed before the events supervise
//! anything: a hot pixel's count says nothing about the light, and read as a brightness change it
//! asks the model for a flickering pixel.
//!
//! Rule: pixel p is hot when its count n_p ≥ `min_events` and n_p ≥ `ratio` · (m_p + 1), with m_p
//! the median of its 8 neighbours' counts (fewer at the border), or when the same holds for its net
//! count |n⁺ − n⁻| with `min_net` in place of `min_events`. A moving edge lights up a pixel's
//! neighbours as much as the pixel itself, so its ratio stays near 1; a hot pixel's neighbours stay
//! at the scene's rate. Where a moving person keeps the neighbours busy too, the net count still
//! tells: a hot pixel fires one polarity, so its net count is a large share of its count (≥
//! `min_net_fraction`), while a scene pixel's events nearly balance. (Not exactly: with a refractory
//! period a pixel that brightens fast and darkens slowly loses more ON than OFF events; on the
//! benchmark's 1 ms sensor the worst pixel nets 157 of 763 events, 21 %.)

use crate::stream::{EventSlice, EventStream, SensorSize};

/// Thresholds of [`hot_pixel_mask`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HotPixelRule {
    /// A hot pixel has at least this many events over the recording.
    pub min_events: u32,
    /// ... and at least this many times (its neighbours' median count + 1).
    pub ratio: f32,
    /// Or: its net count |n⁺ − n⁻| is at least this and `ratio` times its neighbours' median
    /// net count + 1 ...
    pub min_net: u32,
    /// ... and at least this share of its count.
    pub min_net_fraction: f32,
}

impl Default for HotPixelRule {
    /// At least 20 events and 8 × the neighbours' median + 1; or a net count of at least 100, 8 ×
    /// the neighbours' median + 1 and 30 % of the count.
    fn default() -> Self {
        Self {
            min_events: 20,
            ratio: 8.0,
            min_net: 100,
            min_net_fraction: 0.3,
        }
    }
}

/// The hot pixels of `events` (row-major H × W, true = hot) by `rule`; events outside the sensor
/// are ignored.
pub fn hot_pixel_mask(
    events: &EventSlice<'_>,
    sensor: SensorSize,
    rule: HotPixelRule,
) -> Vec<bool> {
    let (w, h) = (sensor.width as usize, sensor.height as usize);
    let mut counts = vec![0u32; w * h];
    let mut net = vec![0i64; w * h];
    for i in 0..events.len() {
        let (x, y) = (events.x[i] as usize, events.y[i] as usize);
        if x < w && y < h {
            counts[y * w + x] += 1;
            net[y * w + x] += i64::from(events.p[i].signum());
        }
    }
    let net: Vec<u32> = net
        .iter()
        .map(|n| n.unsigned_abs().min(u64::from(u32::MAX)) as u32)
        .collect();
    let by_count = towering(&counts, w, h, rule.min_events, rule.ratio);
    let by_net = towering(&net, w, h, rule.min_net, rule.ratio);
    (0..w * h)
        .map(|p| {
            by_count[p] || (by_net[p] && net[p] as f32 >= rule.min_net_fraction * counts[p] as f32)
        })
        .collect()
}

/// Per pixel: `values[p]` ≥ `min` and ≥ `ratio` · (median of its neighbours' values + 1).
fn towering(values: &[u32], w: usize, h: usize, min: u32, ratio: f32) -> Vec<bool> {
    let mut out = vec![false; w * h];
    let mut around = Vec::with_capacity(8);
    for y in 0..h {
        for x in 0..w {
            let n = values[y * w + x];
            if n < min {
                continue;
            }
            around.clear();
            for (dx, dy) in NEIGHBOURS {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if (0..w as i64).contains(&nx) && (0..h as i64).contains(&ny) {
                    around.push(values[ny as usize * w + nx as usize]);
                }
            }
            around.sort_unstable();
            let median = around.get(around.len() / 2).copied().unwrap_or(0);
            out[y * w + x] = n as f32 >= ratio * (median as f32 + 1.0);
        }
    }
    out
}

const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// `events` without those of the pixels `hot` marks (row-major H × W of `sensor`), in order.
pub fn without_pixels(events: &EventSlice<'_>, sensor: SensorSize, hot: &[bool]) -> EventStream {
    let w = sensor.width as usize;
    let mut out = EventStream::with_capacity(events.len());
    out.sensor = Some(sensor);
    for e in events.iter() {
        let i = e.y as usize * w + e.x as usize;
        if !hot.get(i).copied().unwrap_or(false) {
            out.push(e);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{simulate_sequence, EsimConfig};

    #[test]
    fn the_simulators_hot_pixels_are_found_and_a_moving_edge_is_not() {
        // A bright bar sweeping across a 48 × 32 frame, 10 hot pixels at 1 kHz, 0.2 s.
        let (w, h, n) = (48usize, 32usize, 41usize);
        let frames: Vec<Vec<f32>> = (0..n)
            .map(|k| {
                let edge = k as f32 * w as f32 / n as f32;
                (0..w * h)
                    .map(|i| {
                        if ((i % w) as f32 - edge).abs() < 4.0 {
                            0.9
                        } else {
                            0.1
                        }
                    })
                    .collect()
            })
            .collect();
        let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
        let times: Vec<i64> = (0..n as i64).map(|k| k * 5000).collect();
        let hot_config = EsimConfig {
            hot_pixel_fraction: 10.0 / (w * h) as f64,
            hot_pixel_rate_hz: 1000.0,
            refractory_us: 1000,
            ..EsimConfig::default()
        };
        let noisy = simulate_sequence(hot_config, w, h, &times, &refs).expect("simulate");
        let clean_config = EsimConfig {
            hot_pixel_fraction: 0.0,
            ..hot_config
        };
        let clean = simulate_sequence(clean_config, w, h, &times, &refs).expect("simulate");
        let sensor = SensorSize::new(w as u32, h as u32);
        let rule = HotPixelRule::default();
        let found = hot_pixel_mask(&noisy.as_slice(), sensor, rule);
        assert_eq!(found.iter().filter(|&&b| b).count(), 10);
        // Nothing in the scene's own events is hot, and removing the hot pixels leaves exactly the
        // scene's events of the other pixels.
        assert!(!hot_pixel_mask(&clean.as_slice(), sensor, rule).contains(&true));
        let kept = without_pixels(&noisy.as_slice(), sensor, &found);
        let scene_only = without_pixels(&clean.as_slice(), sensor, &found);
        assert_eq!(kept.len(), scene_only.len());
    }
}
