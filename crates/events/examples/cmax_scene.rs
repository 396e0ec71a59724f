//! Contrast-maximisation accuracy and CPU time on the acceptance scene of `tests/cmax.rs`
//! (a textured 96x96 plane; pure translation, and rotation + translation). Settings can be
//! overridden from the environment for experiments: CM_LEVELS, CM_ITERS, CM_LR, CM_SMOOTH, CM_DIV,
//! CM_SIGMA, CM_CURV, CM_AFFINE_ITERS; CM_DIAG=1 also prints the objective at the ground truth and
//! the per-tile velocity error of the finest level. Run: `cargo run -p events --release --example cmax_scene`.

use std::time::Instant;

use events::{flow_from_events, simulate_sequence, CmaxConfig, EsimConfig, SensorSize};

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

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
fn run_case(omega: f64, d: (f64, f64), cm: &CmaxConfig) -> (f64, f64, usize) {
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
    let flow = flow_from_events(&ev.as_slice(), sensor, 0, t_b, cm).expect("cmax");
    if std::env::var("CM_DIAG").is_ok() {
        let tiles = 1usize << (cm.levels - 1);
        let prob = events::CmaxProblem::new(&ev.as_slice(), sensor, 0, t_b, tiles, tiles, cm)
            .expect("problem");
        // Ground-truth tile velocities: displacement over the window at the tile centres.
        let mut gt = Vec::new();
        let mut est = Vec::new();
        for j in 0..tiles {
            for i in 0..tiles {
                let cx = (i as f64 + 0.5) * w as f64 / tiles as f64 - 0.5;
                let cy = (j as f64 + 0.5) * h as f64 / tiles as f64 - 0.5;
                let (gx, gy) = motion(cx, cy, 1.0, omega, d, c);
                gt.push(gx - cx);
                gt.push(gy - cy);
                let (u, v) = flow.at(cx.round() as usize, cy.round() as usize);
                est.push(u as f64);
                est.push(v as f64);
            }
        }
        println!(
            "  objective: ground truth {:.6e}, estimate {:.6e}, zero {:.6e}",
            prob.objective(&gt),
            prob.objective(&est),
            prob.objective(&vec![0.0; gt.len()])
        );
        for a in [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5] {
            let mut v = Vec::new();
            for j in 0..tiles {
                for i in 0..tiles {
                    let cx = (i as f64 + 0.5) * w as f64 / tiles as f64 - 0.5;
                    let cy = (j as f64 + 0.5) * h as f64 / tiles as f64 - 0.5;
                    let (gx, gy) = motion(cx, cy, 1.0, a * omega, d, c);
                    v.push(gx - cx);
                    v.push(gy - cy);
                }
            }
            let (f, g) = prob.objective_and_gradient(&v);
            println!(
                "  rotation x{a}: objective {f:.6e} gradient {:?}",
                g.iter()
                    .take(8)
                    .map(|x| (x * 1e4).round() / 1e4)
                    .collect::<Vec<_>>()
            );
        }
        for j in 0..tiles {
            let row: Vec<String> = (0..tiles)
                .map(|i| {
                    let k = 2 * (j * tiles + i);
                    format!("{:+.1},{:+.1}", est[k] - gt[k], est[k + 1] - gt[k + 1])
                })
                .collect();
            println!("  err {}", row.join(" "));
        }
    }
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

fn main() {
    let d = CmaxConfig::default();
    let cm = CmaxConfig {
        levels: env("CM_LEVELS", d.levels),
        iterations: env("CM_ITERS", d.iterations),
        learning_rate: env("CM_LR", d.learning_rate),
        smoothness: env("CM_SMOOTH", d.smoothness),
        divergence: env("CM_DIV", d.divergence),
        curvature: env("CM_CURV", d.curvature),
        affine_iterations: env("CM_AFFINE_ITERS", d.affine_iterations),
        blur_sigma: env("CM_SIGMA", d.blur_sigma),
        ..d
    };
    println!("{cm:?}");
    for (name, omega, shift) in [
        ("translation (2.5, -1.5)", 0.0, (2.5, -1.5)),
        ("rotation 0.04 + (1.5, 1)", 0.04, (1.5, 1.0)),
    ] {
        let t = Instant::now();
        let (epe, zero, n) = run_case(omega, shift, &cm);
        println!(
            "{name}: EPE {epe:.3} px (zero flow {zero:.3} px, {n} px) in {:.3} s",
            t.elapsed().as_secs_f64()
        );
    }
}
