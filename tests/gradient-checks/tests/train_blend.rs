//! Finite-difference check of the semantic blend (`train::blend`) through the probability
//! parameterisations (one-hot softmax, scalar sigmoid) down to the logits and every blended input.
//!
//! The blend is bilinear in p and the inputs, and p is a smooth function of the logits, so central
//! differences with h = 1e-6 in f64 are exact to ~1e-10; the tolerance
//! |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) leaves orders of magnitude of margin.

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::blend::{blend, blend_backward, BlendInputs, Blended, SemanticMode};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

fn unpack(v: &[f64]) -> BlendInputs<f64> {
    let a3 = |o: usize| [v[o], v[o + 1], v[o + 2]];
    let m3 = |o: usize| [a3(o), a3(o + 3), a3(o + 6)];
    BlendInputs {
        x_def: a3(0),
        x_static: a3(3),
        cov_def: m3(6),
        cov_static: m3(15),
        c_human: a3(24),
        c_scene: a3(27),
    }
}

fn pack(b: &BlendInputs<f64>) -> Vec<f64> {
    let m = |m: &[[f64; 3]; 3]| m.iter().flatten().copied().collect::<Vec<f64>>();
    [
        &b.x_def[..],
        &b.x_static,
        &m(&b.cov_def),
        &m(&b.cov_static),
        &b.c_human,
        &b.c_scene,
    ]
    .concat()
}

fn dot(out: &Blended<f64>, w: &[f64]) -> f64 {
    let cov: Vec<f64> = out.cov.iter().flatten().copied().collect();
    let flat = [&out.x[..], &cov, &out.c].concat();
    flat.iter().zip(w).map(|(a, b)| a * b).sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn blend_gradients_match(
        inputs in prop::collection::vec(-1.0f64..1.0, 30),
        logits in prop::array::uniform2(-4.0f64..4.0),
        cotangent in prop::collection::vec(-1.0f64..1.0, 15),
        scalar in any::<bool>(),
    ) {
        let mode = if scalar { SemanticMode::Scalar } else { SemanticMode::OneHot };
        let logits = &logits[..mode.logits_per_gaussian()];
        let a = unpack(&inputs);
        let loss = |v: &[f64], l: &[f64]| dot(&blend(mode.probability(l), &unpack(v)), &cotangent);
        let p = mode.probability(logits);
        let d_out = Blended {
            x: [cotangent[0], cotangent[1], cotangent[2]],
            cov: [
                [cotangent[3], cotangent[4], cotangent[5]],
                [cotangent[6], cotangent[7], cotangent[8]],
                [cotangent[9], cotangent[10], cotangent[11]],
            ],
            c: [cotangent[12], cotangent[13], cotangent[14]],
        };
        let (d_p, d_in) = blend_backward(p, &a, &d_out);
        let mut d_logits = vec![0.0; logits.len()];
        mode.probability_backward(logits, d_p, &mut d_logits);
        let num_inputs = central_differences(|v| loss(v, logits), &inputs, H);
        let num_logits = central_differences(|l| loss(&inputs, l), logits, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("{mode:?} d inputs"), &num_inputs, &pack(&d_in), TOL);
        checker.check(&format!("{mode:?} d logits"), &num_logits, &d_logits, TOL);
        checker.finish();
    }
}
