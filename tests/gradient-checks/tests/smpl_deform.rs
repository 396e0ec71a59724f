//! Finite-difference checks of `smpl-deform`'s backward passes: Rodrigues, forward kinematics
//! (w.r.t. pose and translation), linear blend skinning of points and of Gaussian rotations
//! (w.r.t. canonical position / quaternion, weights and bone transforms).
//!
//! Tolerance: every checked function is smooth on the sampled domain (trigonometric and polynomial;
//! quaternions are kept at norm ≥ 0.3 away from the normalisation singularity). Central differences
//! with h = 1e-6 in f64 have truncation error ~h²·|f'''| ≈ 1e-12·|f'''| and rounding error
//! ~ε·|L|/h ≈ 1e-10·|L|; with |L| ≲ 10 here that is ≲ 1e-9. We require
//! |num − ana| ≤ 1e-7 + 1e-6·max(|num|, |ana|): a relative error of 1e-6 with an absolute floor two
//! orders above the FD noise and far below real gradient magnitudes (≳ 1e-3).
//! Rodrigues is also checked at tiny angles (|r| ≤ 1e-3), the Taylor branch, with h = 1e-7 so that the
//! probe stays on that branch for most coordinates; the branches agree to ~1e-13 at the switch.

use gradient_checks::{central_differences, symmetric_from_seed, GradientChecker, Tolerance};
use proptest::prelude::*;
use smpl_deform::fk::{forward_kinematics, forward_kinematics_backward};
use smpl_deform::lbs::{lbs_point, lbs_point_backward, lbs_rotation, lbs_rotation_backward};
use smpl_deform::math::{rodrigues, rodrigues_backward, Affine};
use smpl_deform::SMPL_PARENTS;

const TOL: Tolerance = Tolerance::new(1e-7, 1e-6);
const H: f64 = 1e-6;

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn quat_strategy() -> impl Strategy<Value = [f64; 4]> {
    prop::array::uniform4(-1.0f64..1.0).prop_filter("quaternion norm >= 0.3", |q| {
        q.iter().map(|v| v * v).sum::<f64>() > 0.09
    })
}

fn rigidish_bones(seed: u64, nb: usize) -> Vec<Affine<f64>> {
    // Rotations from random axis-angles plus random translations (bone transforms in LBS are rigid,
    // but the backward must not assume it, so add a small non-rigid perturbation too).
    let v = symmetric_from_seed(seed, nb * 18);
    (0..nb)
        .map(|b| {
            let r = rodrigues([2.0 * v[18 * b], 2.0 * v[18 * b + 1], 2.0 * v[18 * b + 2]]);
            let mut a = [0.0; 12];
            for row in 0..3 {
                for col in 0..3 {
                    a[4 * row + col] = r[3 * row + col] + 0.05 * v[18 * b + 3 + 3 * row + col];
                }
                a[4 * row + 3] = 0.5 * v[18 * b + 12 + row];
            }
            a
        })
        .collect()
}

fn convex_weights(seed: u64, nb: usize) -> Vec<f64> {
    let v = symmetric_from_seed(seed, nb);
    let e: Vec<f64> = v.iter().map(|x| (3.0 * x).exp()).collect();
    let s: f64 = e.iter().sum();
    e.iter().map(|x| x / s).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn rodrigues_matches_finite_differences(
        r in prop::array::uniform3(-3.0f64..3.0),
        seed in any::<u64>(),
    ) {
        let g = symmetric_from_seed(seed, 9);
        let loss = |x: &[f64]| dot(&rodrigues([x[0], x[1], x[2]]), &g);
        let mut gm = [0.0; 9];
        gm.copy_from_slice(&g);
        let ana = rodrigues_backward(r, &gm);
        let num = central_differences(loss, &r, H);
        let mut checker = GradientChecker::new();
        checker.check("rodrigues", &num, &ana, TOL);
        checker.finish();
    }

    #[test]
    fn rodrigues_near_zero_matches_finite_differences(
        r in prop::array::uniform3(-1e-3f64..1e-3),
        seed in any::<u64>(),
    ) {
        let g = symmetric_from_seed(seed, 9);
        let loss = |x: &[f64]| dot(&rodrigues([x[0], x[1], x[2]]), &g);
        let mut gm = [0.0; 9];
        gm.copy_from_slice(&g);
        let ana = rodrigues_backward(r, &gm);
        let num = central_differences(loss, &r, 1e-7);
        let mut checker = GradientChecker::new();
        // h = 1e-7: rounding error ε·|L|/h ≈ 2e-9·|L|, so the absolute floor is 1e-7 as above.
        checker.check("rodrigues near 0", &num, &ana, TOL);
        checker.finish();
    }

    #[test]
    fn forward_kinematics_matches_finite_differences(
        seed in any::<u64>(),
        scale in 0.1f64..1.5,
    ) {
        let nj = SMPL_PARENTS.len();
        let pose: Vec<f64> = symmetric_from_seed(seed, 3 * nj).iter().map(|x| scale * x).collect();
        let transl = {
            let t = symmetric_from_seed(seed ^ 1, 3);
            [t[0], t[1], t[2]]
        };
        let joints: Vec<[f64; 3]> = symmetric_from_seed(seed ^ 2, 3 * nj)
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let d_a: Vec<Affine<f64>> = symmetric_from_seed(seed ^ 3, 12 * nj)
            .chunks(12)
            .map(|c| {
                let mut a = [0.0; 12];
                a.copy_from_slice(c);
                a
            })
            .collect();
        let d_j: Vec<[f64; 3]> = symmetric_from_seed(seed ^ 4, 3 * nj)
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let loss = |pose: &[f64], transl: [f64; 3]| {
            let fk = forward_kinematics(pose, transl, &joints, &SMPL_PARENTS);
            let mut l = 0.0;
            for j in 0..nj {
                l += dot(&fk.posed_from_rest[j], &d_a[j]) + dot(&fk.joints_posed[j], &d_j[j]);
            }
            l
        };
        let fk = forward_kinematics(&pose, transl, &joints, &SMPL_PARENTS);
        let grads =
            forward_kinematics_backward(&pose, &joints, &SMPL_PARENTS, &fk, &d_a, Some(&d_j));
        let num_pose = central_differences(|p| loss(p, transl), &pose, H);
        let num_t = central_differences(|t| loss(&pose, [t[0], t[1], t[2]]), &transl, H);
        let mut checker = GradientChecker::new();
        checker.check("fk d/dpose", &num_pose, &grads.pose, TOL);
        checker.check("fk d/dtransl", &num_t, &grads.transl, TOL);
        checker.finish();
    }

    #[test]
    fn lbs_point_matches_finite_differences(
        x in prop::array::uniform3(-1.0f64..1.0),
        seed in any::<u64>(),
    ) {
        let nb = 24;
        let bones = rigidish_bones(seed, nb);
        let w = convex_weights(seed ^ 7, nb);
        let g = symmetric_from_seed(seed ^ 9, 3);
        let d_out = [g[0], g[1], g[2]];
        let mut d_w = vec![0.0; nb];
        let mut d_b = vec![[0.0; 12]; nb];
        let d_x = lbs_point_backward(&w, &bones, x, d_out, &mut d_w, &mut d_b);
        let num_x = central_differences(|p| dot(&lbs_point(&w, &bones, [p[0], p[1], p[2]]), &g), &x, H);
        let num_w = central_differences(|ww| dot(&lbs_point(ww, &bones, x), &g), &w, H);
        let flat: Vec<f64> = bones.iter().flatten().copied().collect();
        let num_b = central_differences(
            |fb| {
                let bb: Vec<Affine<f64>> = fb.chunks(12).map(|c| {
                    let mut a = [0.0; 12];
                    a.copy_from_slice(c);
                    a
                }).collect();
                dot(&lbs_point(&w, &bb, x), &g)
            },
            &flat,
            H,
        );
        let ana_b: Vec<f64> = d_b.iter().flatten().copied().collect();
        let mut checker = GradientChecker::new();
        checker.check("lbs point d/dx", &num_x, &d_x, TOL);
        checker.check("lbs point d/dw", &num_w, &d_w, TOL);
        checker.check("lbs point d/dbones", &num_b, &ana_b, TOL);
        checker.finish();
    }

    #[test]
    fn lbs_rotation_matches_finite_differences(
        q in quat_strategy(),
        seed in any::<u64>(),
    ) {
        let nb = 24;
        let bones = rigidish_bones(seed, nb);
        let w = convex_weights(seed ^ 7, nb);
        let g = symmetric_from_seed(seed ^ 11, 9);
        let mut gm = [0.0; 9];
        gm.copy_from_slice(&g);
        let mut d_w = vec![0.0; nb];
        let mut d_b = vec![[0.0; 12]; nb];
        let d_q = lbs_rotation_backward(&w, &bones, q, &gm, &mut d_w, &mut d_b);
        let num_q = central_differences(
            |p| dot(&lbs_rotation(&w, &bones, [p[0], p[1], p[2], p[3]]), &g),
            &q,
            H,
        );
        let num_w = central_differences(|ww| dot(&lbs_rotation(ww, &bones, q), &g), &w, H);
        let flat: Vec<f64> = bones.iter().flatten().copied().collect();
        let num_b = central_differences(
            |fb| {
                let bb: Vec<Affine<f64>> = fb.chunks(12).map(|c| {
                    let mut a = [0.0; 12];
                    a.copy_from_slice(c);
                    a
                }).collect();
                dot(&lbs_rotation(&w, &bb, q), &g)
            },
            &flat,
            H,
        );
        let ana_b: Vec<f64> = d_b.iter().flatten().copied().collect();
        let mut checker = GradientChecker::new();
        checker.check("lbs rotation d/dq", &num_q, &d_q, TOL);
        checker.check("lbs rotation d/dw", &num_w, &d_w, TOL);
        checker.check("lbs rotation d/dbones", &num_b, &ana_b, TOL);
        checker.finish();
    }
}

#[test]
fn rodrigues_is_exact_identity_at_zero_and_orthonormal() {
    assert_eq!(
        rodrigues([0.0f64; 3]),
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    );
    // Both branches agree at the switch (s = 5·ε^{1/4} ≈ 6.1e-4 for f64) to well below 1e-12.
    let s: f64 = 5.0 * f64::EPSILON.sqrt().sqrt();
    let th = s.sqrt();
    let below = rodrigues([th * (1.0 - 1e-9), 0.0, 0.0]);
    let above = rodrigues([th * (1.0 + 1e-9), 0.0, 0.0]);
    for k in 0..9 {
        assert!((below[k] - above[k]).abs() < 1e-8, "branch jump at {k}");
    }
    let r = rodrigues([0.3, -1.1, 2.0]);
    // RᵀR = I to 1e-14.
    for i in 0..3 {
        for j in 0..3 {
            let v: f64 = (0..3).map(|k| r[3 * k + i] * r[3 * k + j]).sum();
            let e = if i == j { 1.0 } else { 0.0 };
            assert!((v - e).abs() < 1e-14);
        }
    }
}

mod deformation_networks {
    //! End-to-end FD check of the Gaussian deformation (non-rigid MLP → skinning-field MLP → LBS)
    //! w.r.t. canonical positions, log-scales, quaternions, bone transforms, the pose code and a strided subset of
    //! both networks' parameters. Same tolerance and step as above: the pipeline is smooth except at
    //! LeakyReLU kinks, which random inputs hit within h = 1e-6 with probability ~1e-5 per unit.

    use super::*;
    use smpl_deform::deform_net::{
        deform_gaussians, deform_gaussians_backward, CanonicalGaussians, NonRigidNet,
        SkinningField, NR_FEATURE_DIM,
    };
    use smpl_deform::NUM_POSE_FEATURES;

    const N: usize = 3;

    struct Setup {
        nonrigid: NonRigidNet<f64>,
        field: SkinningField<f64>,
        positions: Vec<[f64; 3]>,
        log_scales: Vec<[f64; 3]>,
        quats: Vec<[f64; 4]>,
        bones: Vec<Affine<f64>>,
        pose_code: Vec<f64>,
        cot: Vec<f64>,
    }

    fn setup(seed: u64) -> Setup {
        let box_vertices = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
        let mut nonrigid = NonRigidNet::<f64>::new(&box_vertices, 8, seed).expect("net");
        // The real init zeroes the last layer; perturb it so every layer gets a gradient.
        let np = nonrigid.mlp.params.len();
        let noise = symmetric_from_seed(seed ^ 21, np);
        for (p, r) in nonrigid.mlp.params.iter_mut().zip(&noise) {
            if *p == 0.0 {
                *p = 0.2 * r;
            }
        }
        let field = SkinningField::<f64>::new(&box_vertices, 8, seed ^ 5).expect("field");
        let v = symmetric_from_seed(seed ^ 31, N * 10);
        Setup {
            nonrigid,
            field,
            positions: (0..N)
                .map(|i| [0.7 * v[10 * i], 0.9 * v[10 * i + 1], 0.2 * v[10 * i + 2]])
                .collect(),
            log_scales: (0..N)
                .map(|i| {
                    [
                        v[10 * i + 3] - 4.0,
                        v[10 * i + 4] - 4.0,
                        v[10 * i + 5] - 4.0,
                    ]
                })
                .collect(),
            quats: (0..N)
                .map(|i| {
                    [
                        1.0 + 0.3 * v[10 * i + 6],
                        v[10 * i + 7],
                        v[10 * i + 8],
                        v[10 * i + 9],
                    ]
                })
                .collect(),
            bones: rigidish_bones(seed ^ 41, 24),
            pose_code: symmetric_from_seed(seed ^ 51, NUM_POSE_FEATURES)
                .iter()
                .map(|x| 0.3 * x)
                .collect(),
            cot: symmetric_from_seed(seed ^ 61, N * (3 + 3 + 9 + NR_FEATURE_DIM)),
        }
    }

    fn loss(s: &Setup) -> f64 {
        let g = CanonicalGaussians {
            positions: &s.positions,
            log_scales: &s.log_scales,
            quats: &s.quats,
        };
        let (out, _) =
            deform_gaussians(&s.nonrigid, &s.field, &g, &s.pose_code, &s.bones).expect("fwd");
        let c = &s.cot;
        let mut l = 0.0;
        for i in 0..N {
            let o = i * (15 + NR_FEATURE_DIM);
            l += dot(&out.positions[i], &c[o..o + 3]);
            l += dot(&out.log_scales[i], &c[o + 3..o + 6]);
            l += dot(&out.mats[i], &c[o + 6..o + 15]);
            l += dot(
                &out.features[i * NR_FEATURE_DIM..(i + 1) * NR_FEATURE_DIM],
                &c[o + 15..o + 15 + NR_FEATURE_DIM],
            );
        }
        l
    }

    fn flat<const K: usize>(v: &[[f64; K]]) -> Vec<f64> {
        v.iter().flatten().copied().collect()
    }

    fn unflat<const K: usize>(v: &[f64]) -> Vec<[f64; K]> {
        v.chunks(K)
            .map(|c| {
                let mut a = [0.0; K];
                a.copy_from_slice(c);
                a
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(8))]

        #[test]
        fn deformation_matches_finite_differences(seed in any::<u64>()) {
            let s = setup(seed);
            let g = CanonicalGaussians { positions: &s.positions, log_scales: &s.log_scales, quats: &s.quats };
            let (_, cache) = deform_gaussians(&s.nonrigid, &s.field, &g, &s.pose_code, &s.bones).expect("fwd");
            let c = &s.cot;
            let stride = 15 + NR_FEATURE_DIM;
            let d_pos: Vec<[f64; 3]> = (0..N).map(|i| [c[i * stride], c[i * stride + 1], c[i * stride + 2]]).collect();
            let d_s: Vec<[f64; 3]> = (0..N).map(|i| [c[i * stride + 3], c[i * stride + 4], c[i * stride + 5]]).collect();
            let d_m: Vec<[f64; 9]> = (0..N).map(|i| {
                let mut m = [0.0; 9];
                m.copy_from_slice(&c[i * stride + 6..i * stride + 15]);
                m
            }).collect();
            let d_f: Vec<f64> = (0..N).flat_map(|i| c[i * stride + 15..(i + 1) * stride].to_vec()).collect();
            let mut d_nr = vec![0.0; s.nonrigid.mlp.params.len()];
            let mut d_field = vec![0.0; s.field.mlp.params.len()];
            let grad = deform_gaussians_backward(
                &s.nonrigid, &s.field, &s.bones, &cache, &d_pos, &d_s, &d_m, &d_f, &mut d_nr, &mut d_field,
            ).expect("bwd");

            let mut checker = GradientChecker::new();
            let num = central_differences(|x| { let mut t = setup(seed); t.positions = unflat(x); loss(&t) }, &flat(&s.positions), H);
            checker.check("deform d/dpositions", &num, &flat(&grad.positions), TOL);
            let num = central_differences(|x| { let mut t = setup(seed); t.log_scales = unflat(x); loss(&t) }, &flat(&s.log_scales), H);
            checker.check("deform d/dlog_scales", &num, &flat(&grad.log_scales), TOL);
            let num = central_differences(|x| { let mut t = setup(seed); t.quats = unflat(x); loss(&t) }, &flat(&s.quats), H);
            checker.check("deform d/dquats", &num, &flat(&grad.quats), TOL);
            let num = central_differences(|x| { let mut t = setup(seed); t.bones = unflat(x); loss(&t) }, &flat(&s.bones), H);
            checker.check("deform d/dbones", &num, &flat(&grad.bones), TOL);
            let num = central_differences(|x| { let mut t = setup(seed); t.pose_code = x.to_vec(); loss(&t) }, &s.pose_code, H);
            checker.check("deform d/dpose_code", &num, &grad.pose_code, TOL);
            // Strided parameter subsets (every 7th / 11th) cover every layer of both networks.
            let idx_nr: Vec<usize> = (0..d_nr.len()).step_by(7).collect();
            let p0: Vec<f64> = idx_nr.iter().map(|&k| s.nonrigid.mlp.params[k]).collect();
            let num = central_differences(|x| {
                let mut t = setup(seed);
                for (j, &k) in idx_nr.iter().enumerate() { t.nonrigid.mlp.params[k] = x[j]; }
                loss(&t)
            }, &p0, H);
            let ana: Vec<f64> = idx_nr.iter().map(|&k| d_nr[k]).collect();
            checker.check("deform d/dnonrigid params", &num, &ana, TOL);
            let idx_f: Vec<usize> = (0..d_field.len()).step_by(11).collect();
            let p0: Vec<f64> = idx_f.iter().map(|&k| s.field.mlp.params[k]).collect();
            let num = central_differences(|x| {
                let mut t = setup(seed);
                for (j, &k) in idx_f.iter().enumerate() { t.field.mlp.params[k] = x[j]; }
                loss(&t)
            }, &p0, H);
            let ana: Vec<f64> = idx_f.iter().map(|&k| d_field[k]).collect();
            checker.check("deform d/dfield params", &num, &ana, TOL);
            checker.finish();
        }
    }
}

mod pose_blend_shapes {
    //! FD check of posing a body's vertices (skinning transforms + SMPL pose blend shapes) w.r.t.
    //! the 72 pose values and the translation, on a small random body with the SMPL tree. Same
    //! tolerance and step as above: the function is a polynomial in sines and cosines of the pose.
    //! The pose-blend path is checked on its own too (loss through the offsets only), so a
    //! wrongly-zero blend gradient cannot hide behind the larger skinning-transform gradient.

    use super::*;
    use smpl_deform::pose_blend::{
        pose_blend_offsets, pose_blend_offsets_backward, pose_feature_backward, pose_feature_of,
        pose_vertices, pose_vertices_backward, PosingBody,
    };
    use smpl_deform::{NUM_JOINTS, NUM_POSE_FEATURES};

    const NV: usize = 7;

    struct Body {
        shaped: Vec<[f64; 3]>,
        joints: Vec<[f64; 3]>,
        weights: Vec<f32>,
        posedirs: Vec<f32>,
    }

    fn body(seed: u64) -> Body {
        let v = symmetric_from_seed(seed, NV * 3 + NUM_JOINTS * 3);
        let mut weights = Vec::with_capacity(NV * NUM_JOINTS);
        for k in 0..NV {
            weights.extend(
                convex_weights(seed ^ (k as u64 + 7), NUM_JOINTS)
                    .iter()
                    .map(|&w| w as f32),
            );
        }
        Body {
            shaped: v[..NV * 3].chunks(3).map(|c| [c[0], c[1], c[2]]).collect(),
            joints: v[NV * 3..]
                .chunks(3)
                .map(|c| [0.5 * c[0], c[1], 0.3 * c[2]])
                .collect(),
            weights,
            posedirs: symmetric_from_seed(seed ^ 99, NV * 3 * NUM_POSE_FEATURES)
                .iter()
                .map(|&x| (0.05 * x) as f32)
                .collect(),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]

        #[test]
        fn posing_with_pose_blend_shapes_matches_finite_differences(
            seed in any::<u64>(),
            scale in 0.1f64..1.5,
        ) {
            let b = body(seed);
            let posing = PosingBody {
                shaped: &b.shaped,
                joints_rest: &b.joints,
                parents: &SMPL_PARENTS,
                weights: &b.weights,
                posedirs: Some(&b.posedirs),
            };
            let pose: Vec<f64> = symmetric_from_seed(seed ^ 5, 3 * NUM_JOINTS).iter().map(|x| scale * x).collect();
            let transl = [0.1, -0.2, 0.3];
            let cot: Vec<[f64; 3]> = symmetric_from_seed(seed ^ 6, NV * 3).chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
            let loss = |p: &[f64], t: [f64; 3]| {
                let (v, _) = pose_vertices(&posing, p, t);
                v.iter().zip(&cot).map(|(a, c)| dot(a, c)).sum::<f64>()
            };
            let (_, cache) = pose_vertices(&posing, &pose, transl);
            let g = pose_vertices_backward(&posing, &pose, &cache, &cot);
            let mut checker = GradientChecker::new();
            let num = central_differences(|p| loss(p, transl), &pose, H);
            checker.check("posing d/dpose", &num, &g.pose, TOL);
            let num = central_differences(|t| loss(&pose, [t[0], t[1], t[2]]), &transl, H);
            checker.check("posing d/dtransl", &num, &g.transl, TOL);

            // The pose-blend path alone: L = ⟨offsets(feature(pose)), cot⟩.
            let blend_loss = |p: &[f64]| {
                let rots: Vec<[f64; 9]> = p.chunks(3).map(|r| rodrigues([r[0], r[1], r[2]])).collect();
                let off = pose_blend_offsets(&b.posedirs, &pose_feature_of(&rots));
                off.iter().zip(&cot).map(|(a, c)| dot(a, c)).sum::<f64>()
            };
            let ana = pose_feature_backward(&pose, &pose_blend_offsets_backward(&b.posedirs, &cot));
            let num = central_differences(blend_loss, &pose, H);
            checker.check("pose blend shapes d/dpose", &num, &ana, TOL);
            checker.finish();
            // Joint 0 (global orientation) does not enter the blend feature; every other joint does.
            prop_assert!(ana[..3].iter().all(|&x| x == 0.0));
            prop_assert!(ana[3..].iter().all(|&x| x != 0.0));
        }
    }
}

mod frame_pose {
    //! FD check of a frame's pose as a canonical-space model consumes it (bones from canonical and
    //! pose code) w.r.t. the 72 pose values and the translation, on a random body with the SMPL tree
    //! and random canonical inverses. Same step and tolerance as above (a polynomial in sines and
    //! cosines of the pose). The pose-code path is checked on its own too, so a wrongly-zero code
    //! gradient cannot hide behind the bones' larger one.

    use super::*;
    use smpl_deform::frame_pose::{frame_pose, frame_pose_backward};
    use smpl_deform::{NUM_JOINTS, NUM_POSE_FEATURES};

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]

        #[test]
        fn frame_pose_matches_finite_differences(seed in any::<u64>(), scale in 0.1f64..1.5) {
            let joints: Vec<[f64; 3]> = symmetric_from_seed(seed, 3 * NUM_JOINTS)
                .chunks(3)
                .map(|c| [0.5 * c[0], c[1], 0.3 * c[2]])
                .collect();
            let inverses = rigidish_bones(seed ^ 3, NUM_JOINTS);
            let pose: Vec<f64> = symmetric_from_seed(seed ^ 5, 3 * NUM_JOINTS).iter().map(|x| scale * x).collect();
            let transl = [0.1, -0.2, 0.3];
            let d_bones: Vec<Affine<f64>> = symmetric_from_seed(seed ^ 6, 12 * NUM_JOINTS)
                .chunks(12)
                .map(|c| std::array::from_fn(|k| c[k]))
                .collect();
            let d_code = symmetric_from_seed(seed ^ 7, NUM_POSE_FEATURES);
            let loss = |p: &[f64], t: [f64; 3], code_weight: f64, bone_weight: f64| {
                let f = frame_pose(p, t, &joints, &SMPL_PARENTS, &inverses);
                bone_weight * f.bones.iter().zip(&d_bones).map(|(a, c)| dot(a, c)).sum::<f64>()
                    + code_weight * dot(&f.pose_code, &d_code)
            };
            let f = frame_pose(&pose, transl, &joints, &SMPL_PARENTS, &inverses);
            let g = frame_pose_backward(&pose, &joints, &SMPL_PARENTS, &inverses, &f, &d_bones, &d_code);
            let mut checker = GradientChecker::new();
            let num = central_differences(|p| loss(p, transl, 1.0, 1.0), &pose, H);
            checker.check("frame pose d/dpose", &num, &g.pose, TOL);
            let num = central_differences(|t| loss(&pose, [t[0], t[1], t[2]], 1.0, 1.0), &transl, H);
            checker.check("frame pose d/dtransl", &num, &g.transl, TOL);
            // The pose code alone.
            let zero_bones = vec![[0.0; 12]; NUM_JOINTS];
            let code_only = frame_pose_backward(&pose, &joints, &SMPL_PARENTS, &inverses, &f, &zero_bones, &d_code);
            let num = central_differences(|p| loss(p, transl, 1.0, 0.0), &pose, H);
            checker.check("frame pose code d/dpose", &num, &code_only.pose, TOL);
            checker.finish();
            prop_assert!(code_only.pose[3..].iter().all(|&x| x != 0.0));
        }
    }
}
