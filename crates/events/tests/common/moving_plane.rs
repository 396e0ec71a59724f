//! The contrast-maximisation acceptance scene, shared by `tests/cmax.rs` and
//! `examples/cmax_scene.rs`: simulated events of a textured 96×96 plane that rotates about the image
//! centre and translates with known flow, and the end-point error of an estimate over its textured
//! pixels.

use events::{simulate_sequence, EsimConfig, EventStream, Flow};

/// Sensor width and height (pixels).
pub const SIZE: usize = 96;
/// End of the event window (µs; it starts at 0).
pub const T_END_US: i64 = 10_000;

/// Smooth deterministic texture in (0.1, 0.9): a sum of oriented sinusoids.
fn texture(x: f64, y: f64) -> f64 {
    let waves = [
        (0.31, 0.12, 0.3, 0.12),
        (-0.17, 0.29, 1.1, 0.10),
        (0.45, -0.38, 2.0, 0.06),
        (0.08, 0.52, 0.7, 0.05),
        (-0.41, -0.22, 2.9, 0.05),
    ];
    0.5 + waves
        .iter()
        .map(|&(fx, fy, ph, a)| a * (fx * x + fy * y + ph).sin())
        .sum::<f64>()
}

/// The image centre, about which the plane rotates.
fn centre() -> (f64, f64) {
    ((SIZE as f64 - 1.0) / 2.0, (SIZE as f64 - 1.0) / 2.0)
}

/// Rigid motion of the plane at fraction `s` ∈ [0, 1] of the window: rotation by `omega·s` about
/// the image centre, then translation `d·s`. Returns the image position of texture point (x, y).
pub fn motion(x: f64, y: f64, s: f64, omega: f64, d: (f64, f64)) -> (f64, f64) {
    let c = centre();
    let (sn, cs) = (omega * s).sin_cos();
    let (dx, dy) = (x - c.0, y - c.1);
    (
        c.0 + cs * dx - sn * dy + d.0 * s,
        c.1 + sn * dx + cs * dy + d.1 * s,
    )
}

/// The events of the plane moving by rotation `omega` (rad) and translation `d` (px) over
/// `[0, T_END_US)`, from 25 rendered frames and the ESIM simulator (seeded).
pub fn simulate(omega: f64, d: (f64, f64)) -> EventStream {
    let (w, h) = (SIZE, SIZE);
    let c = centre();
    let sub = 24;
    let times: Vec<i64> = (0..=sub)
        .map(|k| k as i64 * T_END_US / sub as i64)
        .collect();
    let frames: Vec<Vec<f32>> = (0..=sub)
        .map(|k| {
            let s = k as f64 / sub as f64;
            let mut f = vec![0.0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    // Inverse motion: the texture point seen at pixel (x, y) at time s.
                    let (sn, cs) = (omega * s).sin_cos();
                    let (px, py) = (x as f64 - d.0 * s - c.0, y as f64 - d.1 * s - c.1);
                    let (qx, qy) = (c.0 + cs * px + sn * py, c.1 - sn * px + cs * py);
                    f[y * w + x] = texture(qx, qy) as f32;
                }
            }
            f
        })
        .collect();
    let refs: Vec<&[f32]> = frames.iter().map(Vec::as_slice).collect();
    let cfg = EsimConfig {
        c_pos: 0.1,
        c_neg: 0.1,
        sigma: 0.01,
        seed: 7,
        ..EsimConfig::default()
    };
    simulate_sequence(cfg, w, h, &times, &refs).expect("simulate")
}

/// (EPE of `flow`, EPE of the zero flow = mean |ground truth|, textured pixel count) over the pixels
/// with at least one event, against the motion `omega`, `d` over the whole window.
pub fn end_point_error(
    flow: &Flow,
    events: &EventStream,
    omega: f64,
    d: (f64, f64),
) -> (f64, f64, usize) {
    let (w, h) = (SIZE, SIZE);
    let mut has_event = vec![false; w * h];
    for e in events.iter() {
        has_event[e.y as usize * w + e.x as usize] = true;
    }
    let (mut sum, mut zero, mut count) = (0.0, 0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            if !has_event[y * w + x] {
                continue;
            }
            let (gx, gy) = motion(x as f64, y as f64, 1.0, omega, d);
            let (u, v) = flow.at(x, y);
            sum += ((u as f64 - (gx - x as f64)).powi(2) + (v as f64 - (gy - y as f64)).powi(2))
                .sqrt();
            zero += ((gx - x as f64).powi(2) + (gy - y as f64).powi(2)).sqrt();
            count += 1;
        }
    }
    (sum / count as f64, zero / count as f64, count)
}
