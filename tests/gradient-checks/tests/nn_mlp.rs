//! Finite-difference check of `nn::mlp::Mlp` end to end: gradients w.r.t. every parameter and the input.
//!
//! The network is smooth except at the activation kinks (x = 0); cases in which any hidden
//! pre-activation lies within 1e-4 of 0 are rejected, so a probe of h = 1e-6 never crosses a kink.
//! In f64 the tolerance |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|) is then five orders of magnitude
//! above the difference quotient's error.

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use nn::mlp::{Activation, Mlp};
use proptest::prelude::*;

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;

fn min_abs_pre_activation(mlp: &Mlp<f64>, x: &[f64], batch: usize) -> f64 {
    // Recompute hidden pre-activations layer by layer with a truncated copy of the network.
    let mut margin = f64::INFINITY;
    for l in 1..mlp.layers() {
        let mut sub = Mlp::new(&mlp.sizes[..=l], mlp.activation, 0).expect("valid sizes");
        sub.params = mlp.params[..sub.num_params()].to_vec();
        let (y, _) = sub.forward(x, batch).expect("forward");
        margin = y.iter().fold(margin, |m, v| m.min(v.abs()));
    }
    margin
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn mlp_gradients_match(
        sizes in prop::collection::vec(1usize..6, 2..5),
        batch in 1usize..4,
        seed in any::<u64>(),
        leaky in any::<bool>(),
        x_seed in prop::collection::vec(-1.0f64..1.0, 4 * 6),
        cot in prop::collection::vec(-1.0f64..1.0, 4 * 6),
    ) {
        let act = if leaky { Activation::LeakyRelu(0.2) } else { Activation::Relu };
        let mlp = Mlp::<f64>::new(&sizes, act, seed).expect("valid sizes");
        let x = x_seed[..batch * mlp.input_dim()].to_vec();
        let cot = cot[..batch * mlp.output_dim()].to_vec();
        prop_assume!(min_abs_pre_activation(&mlp, &x, batch) > 1e-4);
        let loss = |m: &Mlp<f64>, x: &[f64]| {
            let (y, _) = m.forward(x, batch).expect("forward");
            y.iter().zip(&cot).map(|(a, b)| a * b).sum::<f64>()
        };
        let (_, cache) = mlp.forward(&x, batch).expect("forward");
        let mut d_params = vec![0.0; mlp.num_params()];
        let mut d_x = vec![0.0; x.len()];
        mlp.backward(&cache, &cot, &mut d_params, Some(&mut d_x)).expect("backward");
        let num_params = central_differences(
            |p| {
                let mut m = mlp.clone();
                m.params = p.to_vec();
                loss(&m, &x)
            },
            &mlp.params,
            H,
        );
        let num_x = central_differences(|v| loss(&mlp, v), &x, H);
        let mut checker = GradientChecker::new();
        checker.check(&format!("mlp {sizes:?} params"), &num_params, &d_params, TOL);
        checker.check(&format!("mlp {sizes:?} input"), &num_x, &d_x, TOL);
        checker.finish();
    }
}
