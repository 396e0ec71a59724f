//! As-isometric-as-possible (AIAP) regularisers of 3DGS-Avatar on the human Gaussians: for each Gaussian
//! i and each of its canonical-space nearest neighbours j, the distance between i and j after deformation
//! should equal the distance in canonical space. Applied to positions (3-vectors) and to covariances
//! (the 6 upper-triangular entries Σ00, Σ01, Σ02, Σ11, Σ12, Σ22 as a vector), each as
//! `mean_{i,j} | ‖a_i − a_j‖ − ‖b_i − b_j‖ |` with gradients w.r.t. both the canonical `a` and the
//! deformed `b` values (both are learnable). 3DGS-Avatar uses 5 nearest points including the point itself,
//! i.e. 4 neighbours, found once in canonical space (recomputed here after densification).

use num_traits::Float;

/// Number of canonical-space neighbours per Gaussian (3DGS-Avatar: K = 5 including the point itself).
pub const AIAP_NEIGHBOURS: usize = 4;

/// Euclidean norm of the difference of two D-vectors.
#[inline]
fn dist<T: Float, const D: usize>(a: &[T; D], b: &[T; D]) -> (T, [T; D]) {
    let mut d = [T::zero(); D];
    let mut s = T::zero();
    for k in 0..D {
        d[k] = a[k] - b[k];
        s = s + d[k] * d[k];
    }
    (s.sqrt(), d)
}

/// AIAP loss between `canonical` and `deformed` D-vectors (one per Gaussian) over `neighbours`
/// (`k` indices per Gaussian, row-major). Adds the gradient (scaled by `weight`) into `d_canonical` and
/// `d_deformed` when given, and returns `weight ·` loss. Pairs at zero distance contribute no gradient.
pub fn aiap_loss<T: Float, const D: usize>(
    canonical: &[[T; D]],
    deformed: &[[T; D]],
    neighbours: &[u32],
    k: usize,
    weight: T,
    mut d_canonical: Option<&mut [[T; D]]>,
    mut d_deformed: Option<&mut [[T; D]]>,
) -> T {
    let n = canonical.len();
    if n == 0 || k == 0 {
        return T::zero();
    }
    let count = T::from(n * k).unwrap_or_else(T::one);
    let scale = weight / count;
    let mut total = T::zero();
    for i in 0..n {
        for &j in &neighbours[i * k..(i + 1) * k] {
            let j = j as usize;
            let (dc, vc) = dist(&canonical[i], &canonical[j]);
            let (dd, vd) = dist(&deformed[i], &deformed[j]);
            let diff = dc - dd;
            total = total + diff.abs();
            let sign = super::l1_slope(diff, T::one());
            if let Some(g) = d_canonical.as_deref_mut() {
                if dc > T::zero() {
                    for a in 0..D {
                        let v = scale * sign * vc[a] / dc;
                        g[i][a] = g[i][a] + v;
                        g[j][a] = g[j][a] - v;
                    }
                }
            }
            if let Some(g) = d_deformed.as_deref_mut() {
                if dd > T::zero() {
                    for a in 0..D {
                        let v = scale * sign * vd[a] / dd;
                        g[i][a] = g[i][a] - v;
                        g[j][a] = g[j][a] + v;
                    }
                }
            }
        }
    }
    total * scale
}

/// The 6 upper-triangular entries (Σ00, Σ01, Σ02, Σ11, Σ12, Σ22) of a symmetric 3×3 matrix.
#[inline]
pub fn upper_triangle<T: Float>(m: &[[T; 3]; 3]) -> [T; 6] {
    [m[0][0], m[0][1], m[0][2], m[1][1], m[1][2], m[2][2]]
}

/// Spreads a gradient w.r.t. the 6 upper-triangular entries back to a full 3×3 gradient in which the
/// nine entries are independent (the convention of `gaussians::covariance::covariance_3d_backward`):
/// each off-diagonal entry's gradient goes to the upper entry only, since the 6-vector reads only those.
#[inline]
pub fn upper_triangle_backward<T: Float>(g: &[T; 6]) -> [[T; 3]; 3] {
    let z = T::zero();
    [[g[0], g[1], g[2]], [z, g[3], g[4]], [z, z, g[5]]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_motion_has_zero_loss() {
        let canonical: Vec<[f64; 3]> = (0..8)
            .map(|i| [i as f64, (i * i) as f64 * 0.1, 0.5])
            .collect();
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let deformed: Vec<[f64; 3]> = canonical
            .iter()
            .map(|p| {
                [
                    c * p[0] - s * p[1] + 1.0,
                    s * p[0] + c * p[1] - 2.0,
                    p[2] + 0.5,
                ]
            })
            .collect();
        let f32_pts: Vec<[f32; 3]> = canonical.iter().map(|p| p.map(|v| v as f32)).collect();
        let nn = gaussians::init::knn_indices(&f32_pts, AIAP_NEIGHBOURS);
        let loss = aiap_loss(&canonical, &deformed, &nn, AIAP_NEIGHBOURS, 1.0, None, None);
        assert!(loss.abs() < 1e-12, "{loss}");
        let stretched: Vec<[f64; 3]> = canonical.iter().map(|p| p.map(|v| v * 1.5)).collect();
        assert!(
            aiap_loss(
                &canonical,
                &stretched,
                &nn,
                AIAP_NEIGHBOURS,
                1.0,
                None,
                None
            ) > 0.1
        );
    }
}
