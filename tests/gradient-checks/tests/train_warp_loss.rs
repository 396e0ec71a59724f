//! Finite-difference check of the ideal-estimator flow loss (`train::loss::optical_flow::pair_warp_loss`):
//! two full-resolution renders → bilinear resize to 1/4 (`align_corners = true`) → render k+1 warped
//! back by the fixed target flow (bilinear, border padding) → masked L1 against render k over RGB;
//! differentiated w.r.t. every pixel of both renders.
//!
//! Kinks: for a fixed flow the resize and the warp are linear in the images, so the loss is piecewise
//! linear with kinks only where an L1 residual changes sign. Each probe compares the loss's region
//! signature (the residual signs) at `x ± h` with the centre's and drops probes that straddle a kink
//! (at most 5 %; the count is reported).
//!
//! Tolerance: `abs 1e-9, rel 1e-6`, `h = 1e-6`, f64. On a linear piece the central difference is
//! exact up to rounding, ≈ ε·|L|/h ≈ 1e-10 for an O(1) loss; the gradient entries are O(1/|M|) ≈
//! 1e-3–1e-2 (`|M|` ≤ 64 supervised pixels at 8×8), so a wrong sign, a missing warp transpose or a
//! dropped frame k+1 (whose gradient flows only through the warp) changes entries by ≥ 1e-4 and fails;
//! the test asserts that the negated and the frame-(k+1)-zeroed gradients fail.

use gradient_checks::{central_differences, check_pair_gradient, Tolerance};
use proptest::prelude::*;
use train::loss::optical_flow::{pair_warp_loss, prepare_target, FlowTarget};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const SIDE: usize = 32;
const PLANE: usize = SIDE * SIDE;

/// Loss, region signature and (optionally) the gradient w.r.t. `x` = (render k, render k+1), planar RGB.
fn evaluate(target: &FlowTarget<f64>, x: &[f64], grads: bool) -> (f64, u64, Vec<f64>) {
    let (a, b) = x.split_at(3 * PLANE);
    let out = pair_warp_loss(a, b, SIDE, SIDE, target).expect("warp loss");
    let grad = if grads {
        [out.d_first, out.d_second].concat()
    } else {
        Vec::new()
    };
    (out.loss, out.region_signature, grad)
}

fn check(images: &[f64], flow: &[f64]) {
    let target = prepare_target(flow, None, SIDE, SIDE, SIDE / 4, SIDE / 4, 0.05).expect("target");
    assert!(target.supervised() > 0);
    let x = images.to_vec();
    let (_, centre, analytic) = evaluate(&target, &x, true);
    // Only pixels the 1/4 resize reads have a non-zero gradient; every pixel is probed, so the
    // rest must have a zero analytic gradient where the loss does not depend on them.
    let mut kept = Vec::new();
    let mut numeric = Vec::new();
    let mut probed = 0;
    for i in 0..x.len() {
        probed += 1;
        let mut signatures = Vec::new();
        let d = central_differences(
            |p| {
                let mut full = x.clone();
                full[i] = p[0];
                let (l, sig, _) = evaluate(&target, &full, false);
                signatures.push(sig);
                l
            },
            &[x[i]],
            H,
        );
        if signatures.iter().all(|&sig| sig == centre) {
            kept.push(i);
            numeric.push(d[0]);
        }
    }
    let dropped = probed - kept.len();
    assert!(
        dropped * 20 <= probed,
        "{dropped} of {probed} probes straddled a kink"
    );
    let name = format!("pair warp loss d(render k, render k+1) ({dropped} of {probed} dropped)");
    check_pair_gradient(&name, &numeric, &kept, &analytic, 3 * PLANE, TOL);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    #[test]
    fn pair_warp_loss_image_gradients_match(
        images in prop::collection::vec(0.0f64..1.0, 2 * 3 * PLANE),
        flow in prop::collection::vec(-6.0f64..6.0, 2 * PLANE),
    ) {
        check(&images, &flow);
    }
}
