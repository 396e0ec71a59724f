//! The chunked, fused passes against a slow oracle built from the unfused pieces (`nn::Mlp` on
//! the full, unfolded input; per-point LBS kernels of `crate::lbs`), on a batch that spans
//! several chunks and gradient groups; and bit-identity across thread counts.

use super::deform::conj;
use super::skinning::{softmax_rows, softmax_rows_backward};
use super::*;
use crate::lbs::{lbs_gaussians, lbs_gaussians_backward};
use crate::math::Affine;
use crate::skeleton::{NUM_JOINTS, NUM_POSE_FEATURES};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const N: usize = 1500;

/// `∂L/∂xn` of [`encode`] at `xn` from `∂L/∂encoding`.
fn encode_backward(xn: [f64; 3], d_enc: &[f64]) -> [f64; 3] {
    let mut enc = [0.0; ENC_DIM];
    encode(xn, &mut enc);
    encode_backward_from(&enc, d_enc)
}

/// `n` values uniform in [−1, 1), seeded.
fn uniform(seed: u64, n: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

struct Case {
    nonrigid: NonRigidNet<f64>,
    field: SkinningField<f64>,
    x: Vec<[f64; 3]>,
    s: Vec<[f64; 3]>,
    q: Vec<[f64; 4]>,
    code: Vec<f64>,
    bones: Vec<Affine<f64>>,
    cot: Vec<f64>,
}

fn case() -> Case {
    let verts = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
    let mut nonrigid = NonRigidNet::<f64>::new(&verts, 16, 3).expect("net");
    let noise = uniform(9, nonrigid.mlp.params.len());
    for (p, r) in nonrigid.mlp.params.iter_mut().zip(&noise) {
        if *p == 0.0 {
            *p = 0.1 * r;
        }
    }
    let field = SkinningField::<f64>::new(&verts, 16, 4).expect("field");
    let v = uniform(5, N * 10);
    let bones = (0..NUM_JOINTS)
        .map(|b| {
            let r = uniform(100 + b as u64, 12);
            let mut a = [0.0; 12];
            for k in 0..12 {
                a[k] = if k % 5 == 0 { 1.0 } else { 0.0 } + 0.2 * r[k];
            }
            a
        })
        .collect();
    Case {
        nonrigid,
        field,
        x: (0..N)
            .map(|i| [0.7 * v[10 * i], 0.9 * v[10 * i + 1], 0.2 * v[10 * i + 2]])
            .collect(),
        s: (0..N).map(|i| [v[10 * i + 3] - 4.0; 3]).collect(),
        q: (0..N)
            .map(|i| [1.0, v[10 * i + 7], v[10 * i + 8], v[10 * i + 9]])
            .collect(),
        code: uniform(7, NUM_POSE_FEATURES)
            .iter()
            .map(|x| 0.3 * x)
            .collect(),
        bones,
        cot: uniform(11, N * (15 + NR_FEATURE_DIM)),
    }
}

fn rows<const K: usize>(v: &[f64], off: usize) -> Vec<[f64; K]> {
    let stride = 15 + NR_FEATURE_DIM;
    (0..N)
        .map(|i| std::array::from_fn(|k| v[i * stride + off + k]))
        .collect()
}

fn close(what: &str, a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1e-12f64, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        worst <= 1e-10 * scale,
        "{what}: max abs diff {worst:e} (scale {scale:e})"
    );
}

#[test]
fn chunked_passes_match_the_unfused_oracle() {
    let c = case();
    assert!(N > 4 * rows_per_chunk(&c.nonrigid.mlp, &c.field.mlp));
    let g = CanonicalGaussians {
        positions: &c.x,
        log_scales: &c.s,
        quats: &c.q,
    };
    let (out, cache) = deform_gaussians(&c.nonrigid, &c.field, &g, &c.code, &c.bones).expect("fwd");
    let (d_pos, d_s, d_m) = (
        rows::<3>(&c.cot, 0),
        rows::<3>(&c.cot, 3),
        rows::<9>(&c.cot, 6),
    );
    let d_f: Vec<f64> = (0..N)
        .flat_map(|i| {
            let o = i * (15 + NR_FEATURE_DIM) + 15;
            c.cot[o..o + NR_FEATURE_DIM].to_vec()
        })
        .collect();
    let mut d_nr = vec![0.0; c.nonrigid.mlp.params.len()];
    let mut d_sf = vec![0.0; c.field.mlp.params.len()];
    let grad = deform_gaussians_backward(
        &c.nonrigid,
        &c.field,
        &c.bones,
        &cache,
        &d_pos,
        &d_s,
        &d_m,
        &d_f,
        &mut d_nr,
        &mut d_sf,
    )
    .expect("bwd");

    // Oracle forward.
    let full_in = ENC_DIM + NUM_POSE_FEATURES;
    let mut input = vec![0.0; N * full_in];
    for i in 0..N {
        encode(
            c.nonrigid.norm.apply(c.x[i]),
            &mut input[i * full_in..i * full_in + ENC_DIM],
        );
        input[i * full_in + ENC_DIM..(i + 1) * full_in].copy_from_slice(&c.code);
    }
    let (nr_out, nr_cache) = c.nonrigid.mlp.forward(&input, N).expect("nr");
    let x_nr: Vec<[f64; 3]> = (0..N)
        .map(|i| [0, 1, 2].map(|k| c.x[i][k] + nr_out[i * NR_OUT_DIM + k]))
        .collect();
    let q_nr: Vec<[f64; 4]> = (0..N)
        .map(|i| {
            let o = &nr_out[i * NR_OUT_DIM..];
            quat_mul(c.q[i], [1.0, o[6], o[7], o[8]])
        })
        .collect();
    let mut enc = vec![0.0; N * ENC_DIM];
    for i in 0..N {
        encode(
            c.field.norm.apply(x_nr[i]),
            &mut enc[i * ENC_DIM..(i + 1) * ENC_DIM],
        );
    }
    let (mut w, sf_cache) = c.field.mlp.forward(&enc, N).expect("sf");
    softmax_rows(&mut w);
    let (pos, mats) = lbs_gaussians(&w, &c.bones, &x_nr, &q_nr);
    close("positions", &out.positions.concat(), &pos.concat());
    close("mats", &out.mats.concat(), &mats.concat());
    let feats: Vec<f64> = (0..N)
        .flat_map(|i| nr_out[i * NR_OUT_DIM + 9..(i + 1) * NR_OUT_DIM].to_vec())
        .collect();
    close("features", &out.features, &feats);

    // Oracle backward.
    let lbs = lbs_gaussians_backward(&w, &c.bones, &x_nr, &q_nr, &d_pos, &d_m);
    let mut d_logits = vec![0.0; N * NUM_JOINTS];
    softmax_rows_backward(&w, &lbs.weights, &mut d_logits);
    let mut d_sf_ref = vec![0.0; d_sf.len()];
    let mut d_enc = vec![0.0; N * ENC_DIM];
    c.field
        .mlp
        .backward(&sf_cache, &d_logits, &mut d_sf_ref, Some(&mut d_enc))
        .expect("sf bwd");
    let mut d_nr_out = vec![0.0; N * NR_OUT_DIM];
    let mut d_x_ref = vec![[0.0; 3]; N];
    let mut d_q_ref = vec![[0.0; 4]; N];
    for i in 0..N {
        let gx = encode_backward(c.field.norm.apply(x_nr[i]), &d_enc[i * ENC_DIM..]);
        let dxn = [0, 1, 2].map(|k| lbs.positions[i][k] + gx[k] * c.field.norm.inv_half[k]);
        let o = &nr_out[i * NR_OUT_DIM..];
        let r = [1.0, o[6], o[7], o[8]];
        d_q_ref[i] = quat_mul(lbs.quats[i], conj(r));
        let dr = quat_mul(conj(c.q[i]), lbs.quats[i]);
        let d = &mut d_nr_out[i * NR_OUT_DIM..(i + 1) * NR_OUT_DIM];
        d[..3].copy_from_slice(&dxn);
        d[3..6].copy_from_slice(&d_s[i]);
        d[6..9].copy_from_slice(&dr[1..]);
        d[9..].copy_from_slice(&d_f[i * NR_FEATURE_DIM..(i + 1) * NR_FEATURE_DIM]);
        d_x_ref[i] = dxn;
    }
    let mut d_nr_ref = vec![0.0; d_nr.len()];
    let mut d_in = vec![0.0; N * full_in];
    c.nonrigid
        .mlp
        .backward(&nr_cache, &d_nr_out, &mut d_nr_ref, Some(&mut d_in))
        .expect("nr bwd");
    for i in 0..N {
        let gx = encode_backward(c.nonrigid.norm.apply(c.x[i]), &d_in[i * full_in..]);
        for k in 0..3 {
            d_x_ref[i][k] += gx[k] * c.nonrigid.norm.inv_half[k];
        }
    }
    close("d positions", &grad.positions.concat(), &d_x_ref.concat());
    close("d quats", &grad.quats.concat(), &d_q_ref.concat());
    close("d bones", &grad.bones.concat(), &lbs.bones.concat());
    close("d nonrigid params", &d_nr, &d_nr_ref);
    close("d field params", &d_sf, &d_sf_ref);

    // The standalone field passes agree with the fused ones.
    let (w2, sc) = c.field.forward(&x_nr).expect("field fwd");
    close("field weights", &w2, &w);
    close("cached weights", &cache.skinning().weights(), &w);
    let mut d_sf2 = vec![0.0; d_sf.len()];
    let d_x2 = c
        .field
        .backward(&sc, &lbs.weights, &mut d_sf2)
        .expect("field bwd");
    close("field d params", &d_sf2, &d_sf_ref);
    let gx: Vec<f64> = (0..N)
        .flat_map(|i| {
            let g = encode_backward(c.field.norm.apply(x_nr[i]), &d_enc[i * ENC_DIM..]);
            [0, 1, 2].map(|k| g[k] * c.field.norm.inv_half[k])
        })
        .collect();
    close("field d points", &d_x2.concat(), &gx);
}

fn run_f32(threads: usize) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    pool.install(|| {
        let verts = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
        let mut nonrigid = NonRigidNet::<f32>::new(&verts, 32, 1).expect("net");
        for (k, p) in nonrigid.mlp.params.iter_mut().enumerate() {
            if *p == 0.0 {
                *p = 0.01 * ((k % 7) as f32 - 3.0);
            }
        }
        let field = SkinningField::<f32>::new(&verts, 32, 2).expect("field");
        let v = uniform(3, 5000 * 3);
        let x: Vec<[f32; 3]> = v
            .chunks(3)
            .map(|c| [c[0] as f32, c[1] as f32, 0.2 * c[2] as f32])
            .collect();
        let s = vec![[-4.0f32; 3]; x.len()];
        let q = vec![[1.0f32, 0.1, 0.0, 0.0]; x.len()];
        let code = vec![0.05f32; NUM_POSE_FEATURES];
        let bones =
            vec![[1.0f32, 0.0, 0.0, 0.1, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]; NUM_JOINTS];
        let g = CanonicalGaussians {
            positions: &x,
            log_scales: &s,
            quats: &q,
        };
        let (out, cache) = deform_gaussians(&nonrigid, &field, &g, &code, &bones).expect("fwd");
        let n = x.len();
        let mut d_nr = vec![0.0f32; nonrigid.mlp.params.len()];
        let mut d_sf = vec![0.0f32; field.mlp.params.len()];
        let grad = deform_gaussians_backward(
            &nonrigid,
            &field,
            &bones,
            &cache,
            &out.positions,
            &vec![[0.5f32; 3]; n],
            &out.mats,
            &vec![0.25f32; n * NR_FEATURE_DIM],
            &mut d_nr,
            &mut d_sf,
        )
        .expect("bwd");
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<u32>>();
        let mut params = bits(&d_nr);
        params.extend(bits(&d_sf));
        params.extend(bits(&grad.bones.concat()));
        (
            bits(&out.positions.concat()),
            bits(&grad.positions.concat()),
            params,
        )
    })
}

#[test]
fn results_are_bit_identical_for_any_thread_count() {
    let one = run_f32(1);
    assert_eq!(one, run_f32(2));
    assert_eq!(one, run_f32(3));
}

#[test]
fn skinning_pass_is_reused_bit_for_bit_only_where_nothing_moved() {
    // Identity non-rigid net (zero last layer): the deformation's skinning pass is, bit for bit,
    // the field's own pass at the canonical positions, forward and backward.
    let mut c = case();
    let last = NR_OUT_DIM * (c.nonrigid.mlp.sizes[3] + 1);
    let np = c.nonrigid.mlp.params.len();
    for p in &mut c.nonrigid.mlp.params[np - last..] {
        *p = 0.0;
    }
    let g = CanonicalGaussians {
        positions: &c.x,
        log_scales: &c.s,
        quats: &c.q,
    };
    let (_, cache) = deform_gaussians(&c.nonrigid, &c.field, &g, &c.code, &c.bones).expect("fwd");
    let reused = cache
        .skinning_at(&c.x)
        .expect("Δx ≡ 0: the pass is at the canonical positions");
    let (w, own) = c.field.forward(&c.x).expect("field");
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
    assert_eq!(bits(&reused.weights()), bits(&w));
    let d_w = uniform(77, N * NUM_JOINTS);
    let backward = |sc: &SkinningCache<f64>| {
        let mut d_params = vec![0.0; c.field.mlp.params.len()];
        let d_points = c
            .field
            .backward(sc, &d_w, &mut d_params)
            .expect("field bwd");
        (bits(&d_params), bits(&d_points.concat()))
    };
    assert_eq!(backward(reused), backward(&own));

    // Points one ulp away, or fewer of them, are not where the pass ran.
    let mut nudged = c.x.clone();
    nudged[N / 2][1] = f64::from_bits(nudged[N / 2][1].to_bits() + 1);
    assert!(cache.skinning_at(&nudged).is_none());
    assert!(cache.skinning_at(&c.x[1..]).is_none());
    // A non-rigid net that moves the points.
    let moving = case();
    let (_, cache) =
        deform_gaussians(&moving.nonrigid, &c.field, &g, &c.code, &c.bones).expect("fwd");
    assert!(cache.skinning_at(&c.x).is_none());
    // An identity net wider than the field: the deformation cuts other chunks than the field alone.
    let verts = [[-0.8f32, -1.0, -0.2], [0.8, 0.8, 0.3]];
    let wide = NonRigidNet::<f64>::new(&verts, 64, 3).expect("net");
    assert_ne!(
        rows_per_chunk(&wide.fold(&c.code), &c.field.mlp),
        rows_per_chunk(&c.field.mlp, &c.field.mlp)
    );
    let (_, cache) = deform_gaussians(&wide, &c.field, &g, &c.code, &c.bones).expect("fwd");
    assert!(cache.skinning_at(&c.x).is_none());
}
