//! Each sub-exposure render standing for its whole time slice: the smears of an exposure's passes.
//!
//! The exposure model predicts a blurred frame as the mean of S renders at the midpoint-rule times
//! of its exposure (`pose::exposure`). A Gaussian that moves far between two renders leaves S
//! separate copies in that mean where the camera saw a continuous streak, and the fit softens the
//! person to hide the steps. Rendered instead as the time average over its slice of width E/S, a
//! Gaussian moving by u within the slice is itself blurred: to second order its positions add
//! u uᵀ/12 to its covariance (the variance of a uniform spread), which the rasterizer applies
//! (`rasterize_cpu::CovSplats::smears`, keeping the splat's screen mass).
//!
//! **Displacement** of pass s (renders in time order, posed means p₀ … p_{S−1}): the central
//! difference u_s = (p_{s+1} − p_{s−1}) / 2 inside, the one-sided p₁ − p₀ and p_{S−1} − p_{S−2}
//! at the ends — the motion over one slice at the speed the neighbouring renders imply. A Gaussian
//! whose means are equal in every pass (the static scene) gets a zero smear, which renders with the
//! bits of none. Its backward sends dL/du_s to the neighbours' means, so the body's motion inside
//! the exposure is learned from the streaks' lengths too.

use gaussians::covariance::Mat3;
use nn::Real;
use rayon::prelude::*;

/// The passes (time order) whose means give pass `s`'s displacement, with their weights:
/// u_s = Σ w · p.
fn stencil<T: Real>(s: usize, passes: usize) -> [(usize, T); 2] {
    let half = T::from(0.5).unwrap_or_else(T::zero);
    if s == 0 {
        [(1, T::one()), (0, -T::one())]
    } else if s + 1 == passes {
        [(s, T::one()), (s - 1, -T::one())]
    } else {
        [(s + 1, half), (s - 1, -half)]
    }
}

/// Pass `s`'s displacement of Gaussian `i` over its slice (world, metres), from every pass's
/// means `means` (time order).
fn displacement<T: Real>(means: &[&[[T; 3]]], s: usize, i: usize) -> [T; 3] {
    let [(a, wa), (b, wb)] = stencil::<T>(s, means.len());
    [0, 1, 2].map(|k| wa * means[a][i][k] + wb * means[b][i][k])
}

/// The smear u uᵀ / 12 of every Gaussian in every pass, from the passes' posed means (time
/// order, one slice of N means each); empty with fewer than two passes.
pub fn exposure_smears<T: Real>(means: &[&[[T; 3]]]) -> Vec<Vec<Mat3<T>>> {
    if means.len() < 2 {
        return Vec::new();
    }
    let twelfth = T::one() / T::from(12.0).unwrap_or_else(T::one);
    (0..means.len())
        .map(|s| {
            (0..means[s].len())
                .into_par_iter()
                .map(|i| {
                    let u = displacement(means, s, i);
                    [0, 1, 2].map(|k| [0, 1, 2].map(|l| u[k] * u[l] * twelfth))
                })
                .collect()
        })
        .collect()
}

/// Backward of [`exposure_smears`]: adds to every pass's mean gradients `d_means` (time order)
/// the share of the smears' gradients `d_smears` (same layout; entries independent, as the
/// rasterizer returns them): dL/du = (G + Gᵀ) u / 12 through each pass's stencil. Pass t's
/// gradients receive their shares in pass order of the smears that read them, so the sums do not
/// depend on the threads. Gaussians that do not move add nothing.
pub fn exposure_smears_backward<T: Real>(
    means: &[&[[T; 3]]],
    d_smears: &[&[Mat3<T>]],
    d_means: &mut [&mut [[T; 3]]],
) {
    let passes = means.len();
    if passes < 2 {
        return;
    }
    let twelfth = T::one() / T::from(12.0).unwrap_or_else(T::one);
    // dL/du of every pass's smears (zero where the Gaussian does not move).
    let d_u: Vec<Vec<[T; 3]>> = (0..passes)
        .map(|s| {
            (0..means[s].len())
                .into_par_iter()
                .map(|i| {
                    let u = displacement(means, s, i);
                    let g = &d_smears[s][i];
                    [0, 1, 2].map(|k| {
                        (0..3).fold(T::zero(), |acc, l| acc + (g[k][l] + g[l][k]) * u[l]) * twelfth
                    })
                })
                .collect()
        })
        .collect();
    for (t, d_mean) in d_means.iter_mut().enumerate() {
        let sources: Vec<(usize, T)> = (0..passes)
            .flat_map(|s| stencil::<T>(s, passes).map(|(p, w)| (s, p, w)))
            .filter(|&(_, p, _)| p == t)
            .map(|(s, _, w)| (s, w))
            .collect();
        d_mean.par_iter_mut().enumerate().for_each(|(i, d)| {
            for &(s, w) in &sources {
                let g = d_u[s][i];
                if g.iter().any(|&v| v != T::zero()) {
                    for k in 0..3 {
                        d[k] = d[k] + w * g[k];
                    }
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_static_gaussian_has_a_zero_smear_and_a_moving_one_its_slice_spread() {
        let p = |x: f64| vec![[0.0, 0.0, 2.0], [x, 0.0, 2.0]];
        let (a, b, c) = (p(0.0), p(0.3), p(0.6));
        let smears = exposure_smears(&[&a[..], &b[..], &c[..]]);
        assert_eq!(smears.len(), 3);
        for s in &smears {
            assert_eq!(s[0], [[0.0; 3]; 3]);
            assert!((s[1][0][0] - 0.09 / 12.0).abs() < 1e-15, "{}", s[1][0][0]);
            assert_eq!(s[1][1][1], 0.0);
        }
        assert!(exposure_smears(&[&a[..]]).is_empty());
    }
}
