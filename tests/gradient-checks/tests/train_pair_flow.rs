//! End-to-end finite-difference check of the event-flow loss (`train::loss::optical_flow::pair_flow_loss`,
//! paper §4.4) on a tiny scene: Gaussians' colours → rasterizer (frames k and k+1, the Gaussians moved
//! between them) → bilinear resize to 1/4 (`align_corners = true`) → frozen 2-level SPyNet-style
//! network → masked L1 against a target flow; differentiated w.r.t. the colour channels of both
//! frames' Gaussians through the rasterizer's backward, the resize's backward and the network's input
//! gradient.
//!
//! Kinks: colour channels change no discrete rasterizer decision (visibility, tiles, the α cut and
//! clamp, early stop depend on geometry and opacity only), so the render is linear in them; the
//! network (ReLUs, warp cells, border clamps) and the L1 (residual signs) are piecewise smooth. Each
//! probe compares the loss's region signature at `x ± h` with the centre's and drops probes that
//! straddle a kink (at most 5% may be dropped; the count is reported).
//!
//! Tolerance: `abs 1e-8, rel 1e-5`, `h = 1e-6`, f64. The loss is O(1) and piecewise linear-smooth in
//! the probed coordinates (linear render, smooth network piece, linear L1 piece): rounding in the
//! difference quotient is ≈ ε·|L|/h ≈ 1e-10, truncation ≈ h²·|L'''| ≪ 1e-9. A wrong sign, a dropped
//! frame (the second render's gradient, which flows only through the warp and the network's
//! img2 input) or a missing resize transpose changes entries by O(1e-3–1) and fails; the test asserts
//! that the negated and the second-frame-zeroed gradients fail.

use flow::SpyNet;
use gradient_checks::{central_differences, check_pair_gradient, Tolerance};
use proptest::prelude::*;
use rasterize_cpu::{render, render_backward, Camera, Cotangents, RenderSettings, Splats};
use std::cell::RefCell;
use train::loss::optical_flow::{pair_flow_loss, prepare_target};

const TOL: Tolerance = Tolerance::new(1e-8, 1e-5);
const H: f64 = 1e-6;
const N: usize = 10;
const SIDE: usize = 32;

struct Scene {
    means: [Vec<[f64; 3]>; 2],
    log_scales: Vec<[f64; 3]>,
    quats: Vec<[f64; 4]>,
    opacity_logits: Vec<f64>,
}

fn scene(values: &[f64]) -> Scene {
    let v = |i: usize| values[i % values.len()];
    let first: Vec<[f64; 3]> = (0..N)
        .map(|i| [v(i) * 0.35, v(i + 7) * 0.35, 2.0 + 0.5 * v(i + 13).abs()])
        .collect();
    // Frame k+1: every Gaussian moved by up to ~2 px (at f = 40 px, z ≈ 2 m).
    let second = first
        .iter()
        .enumerate()
        .map(|(i, m)| [m[0] + 0.1 * v(i + 3), m[1] + 0.1 * v(i + 5), m[2]])
        .collect();
    Scene {
        means: [first, second],
        log_scales: (0..N)
            .map(|i| [-1.6 + 0.3 * v(i + 3), -1.6 + 0.3 * v(i + 5), -2.0])
            .collect(),
        quats: (0..N)
            .map(|i| [1.0, 0.3 * v(i + 1), 0.3 * v(i + 2), 0.3 * v(i + 4)])
            .collect(),
        opacity_logits: (0..N).map(|i| 1.0 + v(i + 11)).collect(),
    }
}

/// A 2-level network whose output layers are scaled so the predicted flow is O(1) px.
fn network(seed: u64) -> SpyNet<f64> {
    let mut net = SpyNet::<f64>::random(2, seed);
    for level in &mut net.levels {
        for v in &mut level[4].weight {
            *v *= 30.0;
        }
    }
    net
}

/// Loss, region signature and (optionally) the gradient w.r.t. the colours `x` = (frame k's N×3,
/// frame k+1's N×3).
fn evaluate(
    s: &Scene,
    net: &SpyNet<f64>,
    target: &train::loss::optical_flow::FlowTarget<f64>,
    x: &[f64],
    grads: bool,
) -> (f64, u64, Vec<f64>) {
    let camera = Camera::looking_down_z(SIDE as u32, SIDE as u32, 40.0, 40.0).expect("camera");
    let settings = RenderSettings::default();
    let splats = |k: usize| Splats {
        means: &s.means[k],
        log_scales: &s.log_scales,
        quats: &s.quats,
        opacity_logits: &s.opacity_logits,
        channels: &x[k * 3 * N..(k + 1) * 3 * N],
        num_channels: 3,
    };
    let (a, b) = (splats(0), splats(1));
    let ra = render(&camera, &a, &settings).expect("render k");
    let rb = render(&camera, &b, &settings).expect("render k+1");
    let out = pair_flow_loss(net, &ra.image, &rb.image, SIDE, SIDE, target).expect("flow loss");
    let mut grad = Vec::new();
    if grads {
        for (sp, r, d) in [(&a, &ra, &out.d_first), (&b, &rb, &out.d_second)] {
            let cot = Cotangents {
                image: d,
                alpha: None,
                depth: None,
            };
            let g = render_backward(&camera, sp, &settings, r, &cot).expect("backward");
            grad.extend(g.channels);
        }
    }
    (out.loss, out.region_signature, grad)
}

fn check(values: &[f64], colours: &[f64], flow: &[f64], seed: u64) {
    let s = scene(values);
    let net = network(seed);
    let target = prepare_target(flow, None, SIDE, SIDE, SIDE / 4, SIDE / 4, 0.05).expect("target");
    assert!(target.supervised() > 0);
    let x = colours.to_vec();
    let (_, centre, analytic) = evaluate(&s, &net, &target, &x, true);
    let mut kept = Vec::new();
    let mut numeric = Vec::new();
    for i in 0..x.len() {
        let sigs = RefCell::new(Vec::new());
        let d = central_differences(
            |p| {
                let mut full = x.clone();
                full[i] = p[0];
                let (l, sig, _) = evaluate(&s, &net, &target, &full, false);
                sigs.borrow_mut().push(sig);
                l
            },
            &[x[i]],
            H,
        );
        if sigs.borrow().iter().all(|&sig| sig == centre) {
            kept.push(i);
            numeric.push(d[0]);
        }
    }
    let dropped = x.len() - kept.len();
    assert!(
        dropped * 20 <= x.len(),
        "{dropped} of {} probes straddled a kink",
        x.len()
    );
    let name = format!("pair flow loss d(colours k, k+1) ({dropped} probes dropped)");
    check_pair_gradient(&name, &numeric, &kept, &analytic, 3 * N, TOL);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4))]

    #[test]
    fn pair_flow_loss_colour_gradients_match(
        values in prop::collection::vec(-1.0f64..1.0, 17),
        colours in prop::collection::vec(0.0f64..1.0, 2 * 3 * N),
        flow in prop::collection::vec(-3.0f64..3.0, 2 * SIDE * SIDE),
        seed in any::<u64>(),
    ) {
        check(&values, &colours, &flow, seed);
    }
}
