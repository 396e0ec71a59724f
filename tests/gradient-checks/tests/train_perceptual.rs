//! f64 finite-difference check of the perceptual training term (`train::loss::perceptual::perceptual_term`):
//! LPIPS of the mean of S sub-exposure renders, sRGB-encoded, against an observed frame, with its
//! cotangent reaching every render — the trainer's exact code path, generic, in f64.
//!
//! A reduced random network with the LPIPS structure (`lpips::Lpips::random`) on 35 × 33 images, one
//! render and two, keeps the check to every value of every render in seconds; the network's own
//! gradient is checked, on the shipped weights too, in `lpips.rs`. Render values lie in [0.05, 0.95], away from the
//! sRGB clamp at 0 and 1 and from its linear segment's end at 0.0031308 by far more than the step.
//! Tolerance and kink margins as in `lpips.rs` (`abs 1e-9, rel 1e-6`, h = 1e-6, every ReLU
//! pre-activation and max-pool runner-up gap of the encoded prediction ≥ 1e-4); a render's cotangent
//! planes past the third stay zero.

use gradient_checks::{central_differences, rng, GradientChecker, Tolerance};
use lpips::Lpips;
use rand::Rng;
use train::loss::perceptual::{perceptual_term, srgb_image};
use train::loss::photometric::mean_image;

const H: f64 = 1e-6;
const TOL: Tolerance = Tolerance::new(1e-9, 1e-6);

#[test]
fn perceptual_term_gradient_reaches_every_render() {
    let (height, width) = (35, 33);
    let n = 3 * height * width;
    let net = Lpips::<f64>::random([6, 8, 10, 8, 6], 3);
    let weight = 0.7;
    let mut checker = GradientChecker::new();
    for renders_per_frame in [1usize, 2] {
        let mut draw = 0u64;
        let (renders, observed) = loop {
            let mut r = rng(100 * renders_per_frame as u64 + draw);
            let renders: Vec<Vec<f64>> = (0..renders_per_frame)
                .map(|_| (0..n).map(|_| r.gen_range(0.05..0.95)).collect())
                .collect();
            let observed: Vec<f64> = (0..n).map(|_| r.gen_range(0.05..0.95)).collect();
            let refs: Vec<&[f64]> = renders.iter().map(Vec::as_slice).collect();
            let encoded = srgb_image(&mean_image(&refs, n));
            if net.kink_margin(&encoded, height, width).expect("size") >= 1e-4 {
                break (renders, observed);
            }
            draw += 1;
            assert!(draw < 20, "no test point away from the kinks");
        };
        // Four planes per render, as the trainer's renders carry the human probability too.
        let mut d_renders = vec![vec![0.0; 4 * height * width]; renders_per_frame];
        let refs: Vec<&[f64]> = renders.iter().map(Vec::as_slice).collect();
        let prediction = mean_image(&refs, n);
        perceptual_term(
            &net,
            &prediction,
            &observed,
            height,
            width,
            weight,
            &mut d_renders,
            false,
        )
        .expect("sizes");
        for (s, d) in d_renders.iter().enumerate() {
            assert!(d[n..].iter().all(|&v| v == 0.0), "render {s}: extra planes");
            let numeric = central_differences(
                |p| {
                    let mut probe: Vec<&[f64]> = refs.clone();
                    probe[s] = p;
                    let prediction = mean_image(&probe, n);
                    let mut scratch = vec![vec![0.0; n]; renders_per_frame];
                    perceptual_term(
                        &net,
                        &prediction,
                        &observed,
                        height,
                        width,
                        weight,
                        &mut scratch,
                        false,
                    )
                    .expect("sizes")
                },
                &renders[s],
                H,
            );
            checker.check(
                &format!("perceptual term, render {s} of {renders_per_frame}"),
                &numeric,
                &d[..n],
                TOL,
            );
        }
    }
    checker.finish();
}
