//! `scene::image_io::undistort`: an image recorded through a known lens, undistorted, is the
//! undistorted scene. The scene is a linear ramp (0.01 per pixel); the recorded pixels are the
//! ramp through the inverse lens (inverted to 1e-12), a gently curved function of the recorded
//! position, so bilinear sampling errs by at most |f''|/8 per pixel², measured below 2e-5 here:
//! the tolerance is 1e-4, while a half-pixel convention error (or a wrong coefficient) moves
//! values by ≥ 2.5e-3. The identity lens leaves images alone; masks are sampled by the nearest
//! pixel.

use pinhole::{Camera, Distortion};
use scene::image_io::{undistort, Sampling};

fn camera() -> Camera {
    Camera {
        width: 80,
        height: 60,
        fx: 70.0,
        fy: 72.0,
        cx: 41.0,
        cy: 29.5,
        world_to_camera: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}

/// The undistorted normalised coordinates whose distortion is `(xd, yd)` (fixed-point iteration).
fn undistort_point(d: &Distortion, xd: f64, yd: f64) -> (f64, f64) {
    let (mut x, mut y) = (xd, yd);
    for _ in 0..200 {
        let (fx, fy) = d.distort(x, y);
        x -= fx - xd;
        y -= fy - yd;
    }
    (x, y)
}

#[test]
fn a_recorded_ramp_undistorts_to_the_ramp() {
    let cam = camera();
    let d = Distortion::from_opencv(&[-0.25, 0.08, 0.002, -0.001, -0.01]).expect("5 values");
    let (w, h) = (80usize, 60usize);
    // The scene: value = 0.01·u + 0.005·v + 0.1 at undistorted pixel position (u, v) (centres at
    // i + 0.5).
    let ramp = |u: f64, v: f64| 0.01 * u + 0.005 * v + 0.1;
    let mut recorded = vec![0.0f32; w * h];
    for j in 0..h {
        for i in 0..w {
            let xd = (i as f64 + 0.5 - cam.cx) / cam.fx;
            let yd = (j as f64 + 0.5 - cam.cy) / cam.fy;
            let (x, y) = undistort_point(&d, xd, yd);
            recorded[j * w + i] = ramp(x * cam.fx + cam.cx, y * cam.fy + cam.cy) as f32;
        }
    }
    let out = undistort(&recorded, 1, &cam, &d, Sampling::Bilinear);
    let mut checked = 0;
    for j in 5..h - 5 {
        for i in 5..w - 5 {
            let want = ramp(i as f64 + 0.5, j as f64 + 0.5) as f32;
            assert!(
                (out[j * w + i] - want).abs() < 1e-4,
                "({i}, {j}): {} vs {want}",
                out[j * w + i]
            );
            checked += 1;
        }
    }
    assert!(checked > 3000);
    // The half-pixel convention matters: the same image undistorted as if pixel centres were at
    // integers fails.
    let shifted = Camera {
        cx: cam.cx - 0.5,
        cy: cam.cy - 0.5,
        ..cam.clone()
    };
    let wrong = undistort(&recorded, 1, &shifted, &d, Sampling::Bilinear);
    let worst = (0..w * h)
        .filter(|p| (5..h - 5).contains(&(p / w)) && (5..w - 5).contains(&(p % w)))
        .map(|p| (wrong[p] - ramp((p % w) as f64 + 0.5, (p / w) as f64 + 0.5) as f32).abs())
        .fold(0.0f32, f32::max);
    assert!(worst > 2e-3, "{worst}");
    // Not the identity: the lens moved the samples.
    let moved = (0..w * h)
        .filter(|&p| (out[p] - recorded[p]).abs() > 1e-3)
        .count();
    assert!(moved > w * h / 4, "{moved}");
    // The identity lens leaves the image alone.
    assert_eq!(
        undistort(
            &recorded,
            1,
            &cam,
            &Distortion::default(),
            Sampling::Bilinear
        ),
        recorded
    );
    // Nearest sampling only ever copies recorded values (masks stay binary).
    let mask: Vec<f32> = (0..w * h)
        .map(|p| if p % 7 < 3 { 1.0 } else { 0.0 })
        .collect();
    let m = undistort(&mask, 1, &cam, &d, Sampling::Nearest);
    assert!(m.iter().all(|&v| v == 0.0 || v == 1.0));
}
