//! Contrast-maximisation acceptance: simulated events of a textured plane that translates and
//! rotates with known flow; average end-point error over textured pixels must be ≤ 0.5 px.

#[path = "common/moving_plane.rs"]
mod moving_plane;

use events::{flow_from_events, CmaxConfig, SensorSize};
use moving_plane::{end_point_error, simulate, SIZE, T_END_US};

/// Returns (EPE, EPE of the zero flow = mean |ground truth|, textured pixel count).
fn run_case(omega: f64, d: (f64, f64)) -> (f64, f64, usize) {
    let ev = simulate(omega, d);
    let sensor = SensorSize::new(SIZE as u32, SIZE as u32);
    let flow = flow_from_events(&ev.as_slice(), sensor, 0, T_END_US, &CmaxConfig::default())
        .expect("cmax");
    end_point_error(&flow, &ev, omega, d)
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
