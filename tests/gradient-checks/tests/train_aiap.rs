//! Finite-difference check of the as-isometric-as-possible losses (`train::loss::aiap`) w.r.t. canonical and
//! deformed positions (D = 3) and covariance vectors (D = 6).
//!
//! The loss is piecewise smooth: |·| has a kink where a canonical and a deformed neighbour distance are
//! equal, and ‖·‖ one at zero distance. Random deformations keep every |d_c − d_d| and every distance
//! far above h = 1e-6 (cases that come within 1e-4 of a kink are rejected), so central differences are
//! exact to ~1e-10; the tolerance is |num − ana| ≤ 1e-9 + 1e-6·max(|num|, |ana|).

use gradient_checks::{central_differences, GradientChecker, Tolerance};
use proptest::prelude::*;
use train::loss::aiap::{aiap_loss, AIAP_NEIGHBOURS};

const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);
const H: f64 = 1e-6;
const K: usize = AIAP_NEIGHBOURS;

fn distance_margin<const D: usize>(a: &[[f64; D]], b: &[[f64; D]], nn: &[u32]) -> f64 {
    let d = |v: &[[f64; D]], i: usize, j: usize| {
        (0..D)
            .map(|k| (v[i][k] - v[j][k]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let mut margin = f64::INFINITY;
    for i in 0..a.len() {
        for &j in &nn[i * K..(i + 1) * K] {
            let (dc, dd) = (d(a, i, j as usize), d(b, i, j as usize));
            margin = margin.min((dc - dd).abs()).min(dc).min(dd);
        }
    }
    margin
}

fn check<const D: usize>(canonical: Vec<[f64; D]>, deformed: Vec<[f64; D]>, nn: Vec<u32>) {
    let n = canonical.len();
    let mut d_can = vec![[0.0; D]; n];
    let mut d_def = vec![[0.0; D]; n];
    aiap_loss(
        &canonical,
        &deformed,
        &nn,
        K,
        2.5,
        Some(&mut d_can),
        Some(&mut d_def),
    );
    let flat = |v: &[[f64; D]]| v.iter().flatten().copied().collect::<Vec<f64>>();
    let unflat = |p: &[f64]| {
        p.chunks(D)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect::<Vec<[f64; D]>>()
    };
    let num_can = central_differences(
        |p| aiap_loss(&unflat(p), &deformed, &nn, K, 2.5, None, None),
        &flat(&canonical),
        H,
    );
    let num_def = central_differences(
        |p| aiap_loss(&canonical, &unflat(p), &nn, K, 2.5, None, None),
        &flat(&deformed),
        H,
    );
    let mut checker = GradientChecker::new();
    checker.check(
        &format!("aiap D={D} d canonical"),
        &num_can,
        &flat(&d_can),
        TOL,
    );
    checker.check(
        &format!("aiap D={D} d deformed"),
        &num_def,
        &flat(&d_def),
        TOL,
    );
    checker.finish();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn aiap_position_gradients_match(
        points in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 6..20),
        offsets in prop::collection::vec(prop::array::uniform3(-0.3f64..0.3), 20),
    ) {
        let pts32: Vec<[f32; 3]> = points.iter().map(|p| p.map(|v| v as f32)).collect();
        let nn = gaussians::init::knn_indices(&pts32, K);
        let deformed: Vec<[f64; 3]> = points
            .iter()
            .zip(&offsets)
            .map(|(p, o)| [p[0] + o[0], p[1] + o[1], p[2] + o[2]])
            .collect();
        prop_assume!(distance_margin(&points, &deformed, &nn) > 1e-4);
        check(points, deformed, nn);
    }

    #[test]
    fn aiap_covariance_gradients_match(
        covs in prop::collection::vec(prop::array::uniform6(-1.0f64..1.0), 6..16),
        offsets in prop::collection::vec(prop::array::uniform6(-0.3f64..0.3), 16),
        points in prop::collection::vec(prop::array::uniform3(-1.0f32..1.0), 16),
    ) {
        let nn = gaussians::init::knn_indices(&points[..covs.len()], K);
        let deformed: Vec<[f64; 6]> = covs
            .iter()
            .zip(&offsets)
            .map(|(c, o)| std::array::from_fn(|k| c[k] + o[k]))
            .collect();
        prop_assume!(distance_margin(&covs, &deformed, &nn) > 1e-4);
        check(covs, deformed, nn);
    }
}
