//! Contrast-maximisation accuracy and CPU time on the acceptance scene of `tests/cmax.rs`
//! (a textured 96x96 plane; pure translation, and rotation + translation). Settings can be
//! overridden from the environment for experiments: CM_LEVELS, CM_ITERS, CM_LR, CM_SMOOTH, CM_DIV,
//! CM_SIGMA, CM_CURV, CM_AFFINE_ITERS; CM_DIAG=1 also prints the objective at the ground truth and
//! the per-tile velocity error of the finest level. Run: `cargo run -p events --release --example cmax_scene`.

use std::time::Instant;

#[path = "../tests/common/moving_plane.rs"]
mod moving_plane;

use events::{flow_from_events, CmaxConfig, SensorSize};
use moving_plane::{end_point_error, motion, simulate, SIZE, T_END_US};

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Returns (EPE, EPE of the zero flow = mean |ground truth|, textured pixel count).
fn run_case(omega: f64, d: (f64, f64), cm: &CmaxConfig) -> (f64, f64, usize) {
    let (w, h, t_b) = (SIZE, SIZE, T_END_US);
    let ev = simulate(omega, d);
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
                let (gx, gy) = motion(cx, cy, 1.0, omega, d);
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
                    let (gx, gy) = motion(cx, cy, 1.0, a * omega, d);
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
    end_point_error(&flow, &ev, omega, d)
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
