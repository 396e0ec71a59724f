//! Finite-difference check of the semantic blend (`train::blend`) through the probability
//! parameterisations (one-hot softmax, scalar sigmoid) down to the logits and every blended input.
//!
//! The blend is bilinear in p and the inputs, and p is a smooth function of the logits, except for the
//! quaternion sign alignment, which is constant away from q_def·q_static = 0: cases within 1e-3 of that
//! plane are rejected. With h = 1e-6 in f64 the tolerance |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|)
//! leaves five orders of magnitude of margin over the truncation and rounding error (~1e-10).

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::blend::{blend, blend_backward, BlendInputs, Blended, SemanticMode};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

fn unpack(v: &[f64]) -> BlendInputs<f64> {
    let a3 = |o: usize| [v[o], v[o + 1], v[o + 2]];
    let a4 = |o: usize| [v[o], v[o + 1], v[o + 2], v[o + 3]];
    BlendInputs {
        x_def: a3(0),
        x_static: a3(3),
        s_def: a3(6),
        s_static: a3(9),
        q_def: a4(12),
        q_static: a4(16),
        c_human: a3(20),
        c_scene: a3(23),
    }
}

fn pack(b: &BlendInputs<f64>) -> Vec<f64> {
    [
        &b.x_def[..],
        &b.x_static,
        &b.s_def,
        &b.s_static,
        &b.q_def,
        &b.q_static,
        &b.c_human,
        &b.c_scene,
    ]
    .concat()
}

fn dot(out: &Blended<f64>, w: &[f64]) -> f64 {
    let flat = [&out.x[..], &out.s, &out.q, &out.c].concat();
    flat.iter().zip(w).map(|(a, b)| a * b).sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn blend_gradients_match(
        inputs in prop::collection::vec(-1.0f64..1.0, 26),
        logits in prop::array::uniform2(-4.0f64..4.0),
        cotangent in prop::collection::vec(-1.0f64..1.0, 13),
        scalar in any::<bool>(),
    ) {
        let mode = if scalar { SemanticMode::Scalar } else { SemanticMode::OneHot };
        let logits = &logits[..mode.logits_per_gaussian()];
        let a = unpack(&inputs);
        let qdot: f64 = (0..4).map(|k| a.q_def[k] * a.q_static[k]).sum();
        prop_assume!(qdot.abs() > 1e-3);
        let loss = |v: &[f64], l: &[f64]| dot(&blend(mode.probability(l), &unpack(v)), &cotangent);
        let p = mode.probability(logits);
        let d_out = Blended {
            x: [cotangent[0], cotangent[1], cotangent[2]],
            s: [cotangent[3], cotangent[4], cotangent[5]],
            q: [cotangent[6], cotangent[7], cotangent[8], cotangent[9]],
            c: [cotangent[10], cotangent[11], cotangent[12]],
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
