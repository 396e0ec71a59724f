//! Contrast-maximisation acceptance: simulated events of a textured plane that translates and
//! rotates with known flow; average end-point error over textured pixels must be ≤ 0.5 px.

use events::{flow_from_events, simulate_sequence, CmaxConfig, EsimConfig, SensorSize};

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

/// Rigid motion of the plane at fraction `s` ∈ [0, 1] of the window: rotation by `omega·s` about
/// the image centre, then translation `d·s`. Returns the image position of texture point (x, y).
fn motion(x: f64, y: f64, s: f64, omega: f64, d: (f64, f64), c: (f64, f64)) -> (f64, f64) {
    let (sn, cs) = (omega * s).sin_cos();
    let (dx, dy) = (x - c.0, y - c.1);
    (
        c.0 + cs * dx - sn * dy + d.0 * s,
        c.1 + sn * dx + cs * dy + d.1 * s,
    )
}

/// Returns (EPE, EPE of the zero flow = mean |ground truth|, textured pixel count).
fn run_case(omega: f64, d: (f64, f64)) -> (f64, f64, usize) {
    let (w, h) = (96usize, 96usize);
    let c = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let sub = 24;
    let t_b = 10_000i64;
    let times: Vec<i64> = (0..=sub).map(|k| k as i64 * t_b / sub as i64).collect();
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
    let ev = simulate_sequence(cfg, w, h, &times, &refs).expect("simulate");
    let sensor = SensorSize::new(w as u32, h as u32);
    let flow =
        flow_from_events(&ev.as_slice(), sensor, 0, t_b, &CmaxConfig::default()).expect("cmax");
    // Textured pixels: at least one event in the window.
    let mut has_event = vec![false; w * h];
    for e in ev.iter() {
        has_event[e.y as usize * w + e.x as usize] = true;
    }
    let (mut sum, mut zero, mut count) = (0.0, 0.0, 0usize);
    for y in 0..h {
        for x in 0..w {
            if !has_event[y * w + x] {
                continue;
            }
            let (gx, gy) = motion(x as f64, y as f64, 1.0, omega, d, c);
            let (u, v) = flow.at(x, y);
            sum += ((u as f64 - (gx - x as f64)).powi(2) + (v as f64 - (gy - y as f64)).powi(2))
                .sqrt();
            zero += ((gx - x as f64).powi(2) + (gy - y as f64).powi(2)).sqrt();
            count += 1;
        }
    }
    (sum / count as f64, zero / count as f64, count)
}

#[test]
fn translating_plane_flow_within_half_pixel() {
    let (epe, _, n) = run_case(0.0, (2.5, -1.5));
    eprintln!("translation: EPE {epe:.3} px over {n} textured pixels");
    assert!(n > 4000, "only {n} textured pixels");
    assert!(epe <= 0.5, "EPE {epe:.3} px > 0.5 px");
}

/// Rotation + translation: 0.04 rad over the window (up to 2.7 px of rotational flow at the
/// corners) plus (1.5, 1) px.
#[test]
fn rotating_and_translating_plane_flow_within_half_pixel() {
    let (epe, zero, n) = run_case(0.04, (1.5, 1.0));
    eprintln!(
        "rotation+translation: EPE {epe:.3} px (zero flow {zero:.3} px) over {n} textured pixels"
    );
    assert!(n > 4000, "only {n} textured pixels");
    assert!(epe <= 0.5, "EPE {epe:.3} px > 0.5 px");
}
