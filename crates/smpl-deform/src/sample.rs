//! Uniform-by-area surface sampling of a body mesh, with barycentric skinning weights and face ids:
//! the initial human Gaussians and the skinning loss's targets. Deterministic from an explicit seed
//! (ChaCha8, sequential draws: independent of the thread count). Never allocates per sample.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::skeleton::NUM_JOINTS;

/// Points sampled on a mesh surface.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceSamples {
    /// Sample positions (metres, the mesh's frame).
    pub points: Vec<[f32; 3]>,
    /// Unit outward face normal at each sample (counter-clockwise faces).
    pub normals: Vec<[f32; 3]>,
    /// Index of the face each sample lies on.
    pub face_ids: Vec<u32>,
    /// Barycentric coordinates of each sample w.r.t. its face's three corners.
    pub barycentrics: Vec<[f32; 3]>,
    /// Barycentric interpolation of the corners' skinning weights, row-major `(N, 24)`.
    pub weights: Vec<f32>,
}

fn face_geometry(vertices: &[[f32; 3]], f: &[u32; 3]) -> ([f64; 3], f64) {
    let [a, b, c] = f.map(|i| vertices[i as usize].map(f64::from));
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    (n, 0.5 * len)
}

/// Samples `n` points uniformly by area on the mesh (`weights`: row-major `(V, 24)`).
/// Degenerate (zero-area) faces are never chosen. An empty or zero-area mesh gives no samples.
pub fn sample_surface(
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    weights: &[f32],
    n: usize,
    seed: u64,
) -> SurfaceSamples {
    let mut cdf = Vec::with_capacity(faces.len());
    let mut normals = Vec::with_capacity(faces.len());
    let mut total = 0.0f64;
    for f in faces {
        let (nrm, area) = face_geometry(vertices, f);
        total += area;
        cdf.push(total);
        let l = 2.0 * area;
        normals.push(if l > 0.0 {
            [
                (nrm[0] / l) as f32,
                (nrm[1] / l) as f32,
                (nrm[2] / l) as f32,
            ]
        } else {
            [0.0; 3]
        });
    }
    let mut out = SurfaceSamples::default();
    if !(total > 0.0) {
        return out;
    }
    out.points.reserve(n);
    out.weights.reserve(n * NUM_JOINTS);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..n {
        let t: f64 = rng.gen::<f64>() * total;
        let fi = cdf.partition_point(|&c| c <= t).min(faces.len() - 1);
        let r1: f64 = rng.gen();
        let r2: f64 = rng.gen();
        let s = r1.sqrt();
        let bary = [1.0 - s, s * (1.0 - r2), s * r2];
        let f = faces[fi];
        let mut p = [0.0f64; 3];
        let mut w = [0.0f64; NUM_JOINTS];
        for k in 0..3 {
            let v = vertices[f[k] as usize];
            for c in 0..3 {
                p[c] += bary[k] * f64::from(v[c]);
            }
            let row = &weights[f[k] as usize * NUM_JOINTS..(f[k] as usize + 1) * NUM_JOINTS];
            for j in 0..NUM_JOINTS {
                w[j] += bary[k] * f64::from(row[j]);
            }
        }
        out.points.push(p.map(|x| x as f32));
        out.normals.push(normals[fi]);
        out.face_ids.push(fi as u32);
        out.barycentrics.push(bary.map(|x| x as f32));
        out.weights.extend(w.iter().map(|&x| x as f32));
    }
    out
}
