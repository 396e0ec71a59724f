//! Real spherical harmonics of degree 0–3 with the constants of the INRIA 3DGS code, colour evaluation
//! (`colour = Σ_k basis_k(d) · coeff_k + 0.5`, clamped below at 0) and its backward w.r.t. the
//! coefficients and the (unnormalised) view direction.
//!
//! Coefficient layout everywhere in the workspace: coefficient-major, `coeffs[k * 3 + c]` is
//! coefficient k (0 = DC) of colour channel c, with K = (degree + 1)² coefficients. Generic over
//! [`num_traits::Float`]; never allocates.

use num_traits::Float;

/// Highest supported SH degree.
pub const MAX_SH_DEGREE: usize = 3;
/// Number of SH coefficients at [`MAX_SH_DEGREE`].
pub const MAX_SH_COEFFS: usize = 16;

/// Degree-0 constant, 1 / (2√π).
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
/// Degree-1 constant, √3 / (2√π).
pub const SH_C1: f64 = 0.488_602_511_902_919_9;
/// Degree-2 constants.
pub const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Degree-3 constants.
pub const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Number of coefficients per channel for an SH degree: (degree + 1)².
#[inline]
pub const fn num_sh_coeffs(degree: usize) -> usize {
    (degree + 1) * (degree + 1)
}

/// SH degree for a number of coefficients per channel, if it is a square of 1..=4.
pub fn sh_degree_from_coeffs(k: usize) -> Option<usize> {
    (0..=MAX_SH_DEGREE).find(|&d| num_sh_coeffs(d) == k)
}

#[inline]
fn c<T: Float>(v: f64) -> T {
    // Constants are exactly representable in f64 and rounded once for f32.
    T::from(v).unwrap_or_else(T::zero)
}

/// Evaluates the SH basis of `degree` at a *unit* direction into `out[..num_sh_coeffs(degree)]`.
#[inline]
pub fn sh_basis<T: Float>(degree: usize, dir: [T; 3], out: &mut [T]) {
    let [x, y, z] = dir;
    out[0] = c(SH_C0);
    if degree == 0 {
        return;
    }
    let c1: T = c(SH_C1);
    out[1] = -c1 * y;
    out[2] = c1 * z;
    out[3] = -c1 * x;
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    let two: T = c(2.0);
    let three: T = c(3.0);
    let four: T = c(4.0);
    out[4] = c::<T>(SH_C2[0]) * xy;
    out[5] = c::<T>(SH_C2[1]) * yz;
    out[6] = c::<T>(SH_C2[2]) * (two * zz - xx - yy);
    out[7] = c::<T>(SH_C2[3]) * xz;
    out[8] = c::<T>(SH_C2[4]) * (xx - yy);
    if degree == 2 {
        return;
    }
    out[9] = c::<T>(SH_C3[0]) * y * (three * xx - yy);
    out[10] = c::<T>(SH_C3[1]) * xy * z;
    out[11] = c::<T>(SH_C3[2]) * y * (four * zz - xx - yy);
    out[12] = c::<T>(SH_C3[3]) * z * (two * zz - three * xx - three * yy);
    out[13] = c::<T>(SH_C3[4]) * x * (four * zz - xx - yy);
    out[14] = c::<T>(SH_C3[5]) * z * (xx - yy);
    out[15] = c::<T>(SH_C3[6]) * x * (xx - three * yy);
}

/// Given dL/dbasis (`d_basis[..K]`), returns dL/d(unit direction) by the basis Jacobian (the
/// direction is treated as an unconstrained 3-vector; see [`sh_to_color_backward`] for the
/// normalisation).
#[inline]
pub fn sh_basis_backward<T: Float>(degree: usize, dir: [T; 3], d_basis: &[T]) -> [T; 3] {
    let [x, y, z] = dir;
    let zero = T::zero();
    let (mut gx, mut gy, mut gz) = (zero, zero, zero);
    if degree == 0 {
        return [gx, gy, gz];
    }
    let c1: T = c(SH_C1);
    gy = gy - c1 * d_basis[1];
    gz = gz + c1 * d_basis[2];
    gx = gx - c1 * d_basis[3];
    if degree >= 2 {
        let two: T = c(2.0);
        let k: [T; 5] = [
            c(SH_C2[0]),
            c(SH_C2[1]),
            c(SH_C2[2]),
            c(SH_C2[3]),
            c(SH_C2[4]),
        ];
        let d = &d_basis[4..9];
        gx = gx + d[0] * k[0] * y - d[2] * k[2] * two * x + d[3] * k[3] * z + d[4] * k[4] * two * x;
        gy = gy + d[0] * k[0] * x + d[1] * k[1] * z - d[2] * k[2] * two * y - d[4] * k[4] * two * y;
        gz = gz + d[1] * k[1] * y + d[2] * k[2] * two * two * z + d[3] * k[3] * x;
    }
    if degree >= 3 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let k: [T; 7] = [
            c(SH_C3[0]),
            c(SH_C3[1]),
            c(SH_C3[2]),
            c(SH_C3[3]),
            c(SH_C3[4]),
            c(SH_C3[5]),
            c(SH_C3[6]),
        ];
        let (two, three, four, six, eight): (T, T, T, T, T) =
            (c(2.0), c(3.0), c(4.0), c(6.0), c(8.0));
        let d = &d_basis[9..16];
        // b9 = k0 y (3xx − yy)
        gx = gx + d[0] * k[0] * six * x * y;
        gy = gy + d[0] * k[0] * (three * xx - three * yy);
        // b10 = k1 x y z
        gx = gx + d[1] * k[1] * y * z;
        gy = gy + d[1] * k[1] * x * z;
        gz = gz + d[1] * k[1] * x * y;
        // b11 = k2 y (4zz − xx − yy)
        gx = gx - d[2] * k[2] * two * x * y;
        gy = gy + d[2] * k[2] * (four * zz - xx - three * yy);
        gz = gz + d[2] * k[2] * eight * y * z;
        // b12 = k3 z (2zz − 3xx − 3yy)
        gx = gx - d[3] * k[3] * six * x * z;
        gy = gy - d[3] * k[3] * six * y * z;
        gz = gz + d[3] * k[3] * (six * zz - three * xx - three * yy);
        // b13 = k4 x (4zz − xx − yy)
        gx = gx + d[4] * k[4] * (four * zz - three * xx - yy);
        gy = gy - d[4] * k[4] * two * x * y;
        gz = gz + d[4] * k[4] * eight * x * z;
        // b14 = k5 z (xx − yy)
        gx = gx + d[5] * k[5] * two * x * z;
        gy = gy - d[5] * k[5] * two * y * z;
        gz = gz + d[5] * k[5] * (xx - yy);
        // b15 = k6 x (xx − 3yy)
        gx = gx + d[6] * k[6] * (three * xx - three * yy);
        gy = gy - d[6] * k[6] * six * x * y;
    }
    [gx, gy, gz]
}

/// Normalises a direction; a zero vector stays zero (its basis is then the constant term only for the
/// DC band, and higher bands evaluate to their value at the origin, which is 0).
#[inline]
fn normalize3<T: Float>(v: [T; 3]) -> ([T; 3], T) {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if n > T::zero() {
        ([v[0] / n, v[1] / n, v[2] / n], n)
    } else {
        ([T::zero(); 3], T::zero())
    }
}

/// RGB colour of one Gaussian: `max(0, Σ_k basis_k(d̂) · coeffs[k*3 + c] + 0.5)` where `d̂` is the
/// normalised view direction `dir` (camera centre → Gaussian mean, any length).
/// `coeffs` holds at least `num_sh_coeffs(degree) * 3` values (coefficient-major).
#[inline]
pub fn sh_to_color<T: Float>(degree: usize, coeffs: &[T], dir: [T; 3]) -> [T; 3] {
    let (d, _) = normalize3(dir);
    let mut basis = [T::zero(); MAX_SH_COEFFS];
    sh_basis(degree, d, &mut basis);
    let half: T = c(0.5);
    let mut rgb = [half; 3];
    for k in 0..num_sh_coeffs(degree) {
        for ch in 0..3 {
            rgb[ch] = rgb[ch] + basis[k] * coeffs[k * 3 + ch];
        }
    }
    rgb.map(|v| v.max(T::zero()))
}

/// Backward of [`sh_to_color`]: accumulates dL/dcoeffs into `d_coeffs` (added, same layout) and returns
/// dL/d`dir` for the *unnormalised* direction. Channels clamped at 0 pass no gradient (the clamp's
/// derivative is taken as 0 at and below the threshold, as in the INRIA code).
#[inline]
pub fn sh_to_color_backward<T: Float>(
    degree: usize,
    coeffs: &[T],
    dir: [T; 3],
    d_color: [T; 3],
    d_coeffs: &mut [T],
) -> [T; 3] {
    let (d, norm) = normalize3(dir);
    let mut basis = [T::zero(); MAX_SH_COEFFS];
    sh_basis(degree, d, &mut basis);
    let k_count = num_sh_coeffs(degree);
    let half: T = c(0.5);
    let mut raw = [half; 3];
    for k in 0..k_count {
        for ch in 0..3 {
            raw[ch] = raw[ch] + basis[k] * coeffs[k * 3 + ch];
        }
    }
    let mut d_raw = [T::zero(); 3];
    for ch in 0..3 {
        if raw[ch] > T::zero() {
            d_raw[ch] = d_color[ch];
        }
    }
    let mut d_basis = [T::zero(); MAX_SH_COEFFS];
    for k in 0..k_count {
        let mut acc = T::zero();
        for ch in 0..3 {
            d_coeffs[k * 3 + ch] = d_coeffs[k * 3 + ch] + basis[k] * d_raw[ch];
            acc = acc + coeffs[k * 3 + ch] * d_raw[ch];
        }
        d_basis[k] = acc;
    }
    if norm <= T::zero() {
        return [T::zero(); 3];
    }
    let g = sh_basis_backward(degree, d, &d_basis);
    // Through d̂ = v/|v|: dv = (g − d̂ (d̂·g)) / |v|.
    let dot = d[0] * g[0] + d[1] * g[1] + d[2] * g[2];
    [
        (g[0] - d[0] * dot) / norm,
        (g[1] - d[1] * dot) / norm,
        (g[2] - d[2] * dot) / norm,
    ]
}

/// Converts a linear RGB colour in [0, 1] to the DC coefficient that renders it: (rgb − 0.5) / C0.
#[inline]
pub fn rgb_to_sh_dc(rgb: f32) -> f32 {
    (rgb - 0.5) / SH_C0 as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dc_only_colour_is_view_independent() {
        let coeffs = [rgb_to_sh_dc(0.2), rgb_to_sh_dc(0.6), rgb_to_sh_dc(0.9)];
        let a = sh_to_color(0, &coeffs, [0.0f32, 0.0, 1.0]);
        let b = sh_to_color(0, &coeffs, [1.0f32, -3.0, 0.5]);
        assert_eq!(a, b);
        assert!(
            (a[0] - 0.2).abs() < 1e-6 && (a[1] - 0.6).abs() < 1e-6 && (a[2] - 0.9).abs() < 1e-6
        );
    }

    #[test]
    fn basis_is_orthonormal_on_the_sphere() {
        // Monte-Carlo-free check: a Fibonacci sphere quadrature of basis_i · basis_j ≈ δ_ij / (4π)·4π.
        let n = 20_000;
        let mut gram = [[0.0f64; 16]; 16];
        let golden = std::f64::consts::PI * (3.0 - 5.0f64.sqrt());
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            let mut b = [0.0f64; 16];
            sh_basis(3, [r * phi.cos(), r * phi.sin(), z], &mut b);
            for a in 0..16 {
                for c in 0..16 {
                    gram[a][c] += b[a] * b[c] * 4.0 * std::f64::consts::PI / n as f64;
                }
            }
        }
        for a in 0..16 {
            for c in 0..16 {
                let want = if a == c { 1.0 } else { 0.0 };
                assert!(
                    (gram[a][c] - want).abs() < 2e-3,
                    "({a},{c}) = {}",
                    gram[a][c]
                );
            }
        }
    }
}
