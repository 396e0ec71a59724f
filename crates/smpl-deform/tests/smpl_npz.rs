//! SMPL `.npz` loader and posing tests on synthetic files with SMPL's real shapes and dtypes
//! (6890 vertices, 13776 faces, 10 betas, 207 pose features, 24 joints), written by the test itself.

use std::io::Cursor;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use smpl_deform::npz::NpzWriter;
use smpl_deform::{BodyModel, SmplDeformError, SmplParams, NUM_JOINTS, SMPL_PARENTS};

const NV: usize = 6890;
const NF: usize = 13776;
const NB: usize = 10;
const NP: usize = 207;

/// Joints whose rotation moves the left forearm: left elbow and its descendants.
const LEFT_FOREARM: [usize; 3] = [18, 20, 22];

struct Synthetic {
    v_template: Vec<f64>,
    shapedirs: Vec<f64>,
    posedirs: Vec<f64>, // (V, 3, 207)
    j_regressor: Vec<f64>,
    weights: Vec<f64>,
    faces: Vec<u32>,
}

fn synthetic() -> Synthetic {
    let mut r = ChaCha8Rng::seed_from_u64(42);
    let v_template: Vec<f64> = (0..NV * 3).map(|_| r.gen_range(-0.5..0.5)).collect();
    let shapedirs: Vec<f64> = (0..NV * 3 * NB)
        .map(|_| 0.01 * r.gen_range(-0.5..0.5))
        .collect();
    let mut weights = vec![0.0; NV * NUM_JOINTS];
    let mut posedirs = vec![0.0; NV * 3 * NP];
    for v in 0..NV {
        // Two joints per vertex, convex weights.
        let a = r.gen_range(0..NUM_JOINTS);
        let b = r.gen_range(0..NUM_JOINTS);
        let t: f64 = r.gen();
        weights[v * NUM_JOINTS + a] += t;
        weights[v * NUM_JOINTS + b] += 1.0 - t;
        let on_forearm = LEFT_FOREARM
            .iter()
            .any(|&j| weights[v * NUM_JOINTS + j] > 0.0);
        for c in 0..3 {
            for p in 0..NP {
                // Like SMPL, the elbow's pose-blend features only move the vertices it drives.
                let joint = 1 + p / 9;
                let local = joint != 18 || on_forearm;
                if local {
                    posedirs[(v * 3 + c) * NP + p] = 0.001 * r.gen_range(-0.5..0.5);
                }
            }
        }
    }
    let mut j_regressor = vec![0.0; NUM_JOINTS * NV];
    for j in 0..NUM_JOINTS {
        for k in 0..4 {
            j_regressor[j * NV + (j * 97 + k * 13) % NV] = 0.25;
        }
    }
    let faces: Vec<u32> = (0..NF * 3).map(|i| ((i * 7919) % NV) as u32).collect();
    Synthetic {
        v_template,
        shapedirs,
        posedirs,
        j_regressor,
        weights,
        faces,
    }
}

#[derive(Clone, Copy)]
struct Variant {
    f64_data: bool,
    flat_posedirs: bool,
    kintree_u32: bool,
}

fn write_npz(
    s: &Synthetic,
    var: Variant,
    skip: Option<&str>,
    edit: impl Fn(&str, &mut Vec<f64>, &mut Vec<u64>),
) -> Vec<u8> {
    let mut w = NpzWriter::new(Cursor::new(Vec::new()), false);
    let mut floats: Vec<(&str, Vec<f64>, Vec<u64>)> = vec![
        ("v_template", s.v_template.clone(), vec![NV as u64, 3]),
        (
            "shapedirs",
            s.shapedirs.clone(),
            vec![NV as u64, 3, NB as u64],
        ),
        (
            "J_regressor",
            s.j_regressor.clone(),
            vec![NUM_JOINTS as u64, NV as u64],
        ),
        (
            "weights",
            s.weights.clone(),
            vec![NV as u64, NUM_JOINTS as u64],
        ),
    ];
    if var.flat_posedirs {
        let mut flat = vec![0.0; NP * 3 * NV];
        for vc in 0..3 * NV {
            for p in 0..NP {
                flat[p * 3 * NV + vc] = s.posedirs[vc * NP + p];
            }
        }
        floats.push(("posedirs", flat, vec![NP as u64, 3 * NV as u64]));
    } else {
        floats.push((
            "posedirs",
            s.posedirs.clone(),
            vec![NV as u64, 3, NP as u64],
        ));
    }
    for (key, mut data, mut shape) in floats {
        if skip == Some(key) {
            continue;
        }
        edit(key, &mut data, &mut shape);
        let n: u64 = shape.iter().product();
        data.resize(n as usize, 0.0);
        if var.f64_data {
            w.add_f64(key, &shape, &data).expect("write");
        } else {
            let d: Vec<f32> = data.iter().map(|&x| x as f32).collect();
            w.add_f32(key, &shape, &d).expect("write");
        }
    }
    if skip != Some("f") {
        let mut f: Vec<f64> = s.faces.iter().map(|&x| f64::from(x)).collect();
        let mut shape = vec![NF as u64, 3];
        edit("f", &mut f, &mut shape);
        f.resize(shape.iter().product::<u64>() as usize, 0.0);
        if f.iter().all(|&x| x >= 0.0) {
            let d: Vec<u32> = f.iter().map(|&x| x as u32).collect();
            w.add_u32("f", &shape, &d).expect("write");
        } else {
            let d: Vec<i64> = f.iter().map(|&x| x as i64).collect();
            w.add_i64("f", &shape, &d).expect("write");
        }
    }
    if skip != Some("kintree_table") {
        let mut kt = vec![0.0f64; 2 * NUM_JOINTS];
        for j in 0..NUM_JOINTS {
            kt[j] = SMPL_PARENTS[j].map_or(-1.0, |p| p as f64);
            kt[NUM_JOINTS + j] = j as f64;
        }
        let mut shape = vec![2, NUM_JOINTS as u64];
        edit("kintree_table", &mut kt, &mut shape);
        kt.resize(shape.iter().product::<u64>() as usize, 0.0);
        if var.kintree_u32 {
            let d: Vec<u32> = kt
                .iter()
                .map(|&x| if x < 0.0 { u32::MAX } else { x as u32 })
                .collect();
            w.add_u32("kintree_table", &shape, &d).expect("write");
        } else {
            let d: Vec<i64> = kt.iter().map(|&x| x as i64).collect();
            w.add_i64("kintree_table", &shape, &d).expect("write");
        }
    }
    w.finish().expect("finish").into_inner()
}

const PLAIN: Variant = Variant {
    f64_data: false,
    flat_posedirs: false,
    kintree_u32: true,
};

fn no_edit(_: &str, _: &mut Vec<f64>, _: &mut Vec<u64>) {}

/// The error, or "Ok" (never the whole model: it is megabytes of numbers).
fn brief(r: &Result<BodyModel, SmplDeformError>) -> String {
    match r {
        Ok(_) => "Ok(model)".into(),
        Err(e) => e.to_string(),
    }
}

fn load(bytes: Vec<u8>) -> Result<BodyModel, SmplDeformError> {
    BodyModel::load_smpl_npz_from(Cursor::new(bytes))
}

#[test]
fn all_variants_load_to_the_same_model() {
    let s = synthetic();
    let base = load(write_npz(&s, PLAIN, None, no_edit)).expect("f32 file loads");
    assert_eq!(base.num_vertices(), NV);
    assert_eq!(base.faces.len(), NF);
    assert_eq!(base.num_betas, NB);
    assert!(base.has_smpl_tree());
    for var in [
        Variant {
            f64_data: true,
            flat_posedirs: false,
            kintree_u32: false,
        },
        Variant {
            f64_data: false,
            flat_posedirs: true,
            kintree_u32: false,
        },
        Variant {
            f64_data: true,
            flat_posedirs: true,
            kintree_u32: true,
        },
    ] {
        let m = load(write_npz(&s, var, None, no_edit)).expect("variant loads");
        // f64 on disk is rounded to f32 on load, so all variants agree exactly.
        assert_eq!(m.posedirs, base.posedirs);
        assert_eq!(m.v_template, base.v_template);
        assert_eq!(m.parents, base.parents);
    }
}

#[test]
fn zero_pose_reproduces_shaped_template_exactly() {
    let s = synthetic();
    let m = load(write_npz(&s, PLAIN, None, no_edit)).expect("loads");
    let betas: Vec<f32> = (0..NB).map(|k| (k as f32 - 4.5) * 0.3).collect();
    let posed = m
        .pose(&SmplParams {
            pose: vec![0.0; 72],
            betas: betas.clone(),
            transl: [0.0; 3],
        })
        .expect("poses");
    let sd = m.shapedirs.as_ref().expect("shapedirs");
    for v in 0..NV {
        for c in 0..3 {
            let mut expected = m.v_template[v][c];
            for k in 0..NB {
                expected += sd[(3 * v + c) * NB + k] * betas[k];
            }
            assert_eq!(posed.vertices[v][c], expected, "vertex {v} coord {c}");
        }
    }
}

#[test]
fn elbow_bend_moves_only_forearm_vertices() {
    let s = synthetic();
    let m = load(write_npz(&s, PLAIN, None, no_edit)).expect("loads");
    let rest = m.pose(&SmplParams::zero()).expect("rest");
    let mut p = SmplParams::zero();
    p.pose[3 * 18 + 1] = std::f32::consts::FRAC_PI_2; // 90° about y at the left elbow
    let bent = m.pose(&p).expect("bent");
    let (mut moved_arm, mut arm) = (0, 0);
    for v in 0..NV {
        let on_arm = LEFT_FOREARM
            .iter()
            .any(|&j| m.weights[v * NUM_JOINTS + j] > 0.0);
        let d: f32 = (0..3)
            .map(|c| (bent.vertices[v][c] - rest.vertices[v][c]).abs())
            .sum();
        if on_arm {
            arm += 1;
            if d > 1e-4 {
                moved_arm += 1;
            }
        } else {
            assert_eq!(
                bent.vertices[v], rest.vertices[v],
                "non-arm vertex {v} moved"
            );
        }
    }
    assert!(
        arm > 0 && moved_arm * 10 > arm * 9,
        "{moved_arm} of {arm} arm vertices moved"
    );
}

#[test]
fn missing_key_is_named() {
    let s = synthetic();
    for key in [
        "v_template",
        "shapedirs",
        "posedirs",
        "J_regressor",
        "weights",
        "kintree_table",
        "f",
    ] {
        match load(write_npz(&s, PLAIN, Some(key), no_edit)) {
            Err(SmplDeformError::MissingKey { key: k }) => assert_eq!(k, key),
            other => panic!("{key}: expected MissingKey, got {}", brief(&other)),
        }
    }
}

#[test]
fn wrong_shape_is_named() {
    let s = synthetic();
    for key in [
        "v_template",
        "shapedirs",
        "posedirs",
        "J_regressor",
        "weights",
        "kintree_table",
        "f",
    ] {
        let bytes = write_npz(&s, PLAIN, None, |k, _, shape| {
            if k == key {
                shape[1] += 1; // (V,3)->(V,4), (V,3,B)->(V,4,B), (24,V)->(24,V+1), ...
            }
        });
        match load(bytes) {
            Err(SmplDeformError::WrongShape { key: k, .. }) => assert_eq!(k, key),
            other => panic!("{key}: expected WrongShape, got {}", brief(&other)),
        }
    }
}

#[test]
fn nan_is_named() {
    let s = synthetic();
    for key in [
        "v_template",
        "shapedirs",
        "posedirs",
        "J_regressor",
        "weights",
    ] {
        let bytes = write_npz(&s, PLAIN, None, |k, data, _| {
            if k == key {
                data[5] = f64::NAN;
            }
        });
        match load(bytes) {
            Err(SmplDeformError::NonFinite { key: k, index }) => {
                assert_eq!(k, key);
                assert_eq!(index, 5);
            }
            other => panic!("{key}: expected NonFinite, got {}", brief(&other)),
        }
    }
}

#[test]
fn bad_faces_and_weights_are_named() {
    let s = synthetic();
    for bad in [NV as f64, -1.0] {
        let bytes = write_npz(&s, PLAIN, None, |k, data, _| {
            if k == "f" {
                data[4] = bad;
            }
        });
        match load(bytes) {
            Err(SmplDeformError::IndexOutOfRange { key, index, bound }) => {
                assert_eq!((key.as_str(), index, bound), ("f", bad as i64, NV));
            }
            other => panic!(
                "face index {bad}: expected IndexOutOfRange, got {}",
                brief(&other)
            ),
        }
    }
    // A weight row that is not a convex combination (sums to 1.5).
    let bytes = write_npz(&s, PLAIN, None, |k, data, _| {
        if k == "weights" {
            data[3 * NUM_JOINTS] += 0.5;
        }
    });
    match load(bytes) {
        Err(SmplDeformError::BadArray { key, message }) => {
            assert_eq!(key, "weights");
            assert!(message.contains("row 3"), "{message}");
        }
        other => panic!("expected BadArray, got {}", brief(&other)),
    }
}

#[test]
fn kinematic_tree_that_is_not_a_tree_is_rejected() {
    let s = synthetic();
    // A cycle (4 -> 7 -> 4), a second root, a self-parent, a root with a parent.
    let cases: [(usize, f64); 4] = [(4, 7.0), (5, -1.0), (9, 9.0), (0, 3.0)];
    for (joint, parent) in cases {
        let bytes = write_npz(
            &s,
            Variant {
                kintree_u32: false,
                ..PLAIN
            },
            None,
            |k, data, _| {
                if k == "kintree_table" {
                    data[joint] = parent;
                }
            },
        );
        match load(bytes) {
            Err(SmplDeformError::NotATree { key, .. }) => assert_eq!(key, "kintree_table"),
            other => panic!(
                "joint {joint} parent {parent}: expected NotATree, got {}",
                brief(&other)
            ),
        }
    }
}

#[test]
fn bad_params_are_errors() {
    let s = synthetic();
    let m = load(write_npz(&s, PLAIN, None, no_edit)).expect("loads");
    let mut p = SmplParams::zero();
    p.pose.pop();
    assert!(
        matches!(m.pose(&p), Err(SmplDeformError::InvalidParams { field, .. }) if field == "pose")
    );
    let mut p = SmplParams::zero();
    p.betas = vec![0.0; NB + 1];
    assert!(
        matches!(m.pose(&p), Err(SmplDeformError::InvalidParams { field, .. }) if field == "betas")
    );
    let mut p = SmplParams::zero();
    p.transl[1] = f32::NAN;
    assert!(
        matches!(m.pose(&p), Err(SmplDeformError::InvalidParams { field, .. }) if field == "transl")
    );
}

#[test]
fn generic_posing_and_its_backward_agree_with_pose() {
    // The f64 posing of `pose_blend` (used by pose_backward and the FD checks) is the same function
    // as BodyModel::pose, pose blend shapes included; and pose_backward's gradient matches a
    // finite difference of BodyModel::pose itself (f32, so a loose tolerance).
    let s = synthetic();
    let m = load(write_npz(&s, PLAIN, None, no_edit)).expect("loads");
    let mut p = SmplParams::zero();
    for (k, x) in p.pose.iter_mut().enumerate() {
        *x = 0.3 * (((k * 37) % 11) as f32 / 11.0 - 0.5);
    }
    p.transl = [0.1, 0.2, -0.3];
    p.betas = vec![0.5; NB];
    let posed = m.pose(&p).expect("pose");
    let shaped: Vec<[f64; 3]> = m
        .shaped_vertices(&p.betas)
        .expect("shaped")
        .iter()
        .map(|v| v.map(f64::from))
        .collect();
    let joints: Vec<[f64; 3]> = m
        .rest_joints(&m.shaped_vertices(&p.betas).expect("shaped"))
        .iter()
        .map(|v| v.map(f64::from))
        .collect();
    let body = smpl_deform::pose_blend::PosingBody {
        shaped: &shaped,
        joints_rest: &joints,
        parents: &m.parents,
        weights: &m.weights,
        posedirs: m.posedirs.as_deref(),
    };
    let pose64: Vec<f64> = p.pose.iter().map(|&x| f64::from(x)).collect();
    let (v64, _) = smpl_deform::pose_blend::pose_vertices(&body, &pose64, p.transl.map(f64::from));
    let worst = posed
        .vertices
        .iter()
        .zip(&v64)
        .flat_map(|(a, b)| (0..3).map(move |c| (f64::from(a[c]) - b[c]).abs()))
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-5, "f32 pose vs f64 posing: {worst} m");

    // Gradient of L = Σ posed.x (all vertices) w.r.t. an elbow angle, vs a central difference
    // of the f32 model with h = 1e-2 rad (f32 rounding ~1e-7 m per vertex).
    let d_v = vec![[1.0f32, 0.0, 0.0]; m.num_vertices()];
    let (d_pose, d_transl) = m.pose_backward(&p, &d_v).expect("backward");
    // Translation moves every vertex rigidly: ∂L/∂transl = (V, 0, 0) up to the weights' rounding.
    assert!(
        (d_transl[0] - m.num_vertices() as f32).abs() < 1e-2,
        "{d_transl:?}"
    );
    assert!(
        d_transl[1].abs() < 1e-3 && d_transl[2].abs() < 1e-3,
        "{d_transl:?}"
    );
    let sum_x = |q: &SmplParams| -> f64 {
        m.pose(q)
            .expect("pose")
            .vertices
            .iter()
            .map(|v| f64::from(v[0]))
            .sum()
    };
    for k in [3 * 18 + 1, 3 * 18 + 2, 3 * 4] {
        let h = 1e-2f32;
        let (mut a, mut b) = (p.clone(), p.clone());
        a.pose[k] += h;
        b.pose[k] -= h;
        let num = (sum_x(&a) - sum_x(&b)) / (2.0 * f64::from(h));
        let ana = f64::from(d_pose[k]);
        assert!(
            (num - ana).abs() <= 1e-2 * num.abs().max(ana.abs()) + 1e-3,
            "pose[{k}]: numeric {num}, analytic {ana}"
        );
    }
    assert!(matches!(
        m.pose_backward(&p, &d_v[1..]),
        Err(SmplDeformError::InvalidParams { field, .. }) if field == "d_vertices"
    ));
}
