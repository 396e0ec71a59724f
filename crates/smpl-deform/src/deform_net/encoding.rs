//! The position encoding both networks read: a canonical point normalised by the canonical body's
//! padded bounding box ([`Normalizer`]), then the frequency encoding [`encode`] and its backward.
//! Pure per-point functions: no network, no chunking.

use nn::Real;

/// Octaves of the frequency encoding.
pub const NUM_FREQS: usize = 4;
/// Width of the position encoding (3 + 6·L).
pub const ENC_DIM: usize = 3 + 6 * NUM_FREQS;

/// Maps canonical positions (metres) to the box-normalised frame: `(x − centre) / half_extent`.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer<T> {
    /// Box centre (metres).
    pub centre: [T; 3],
    /// 1 / (half extent · 1.1) per axis (1/metres).
    pub inv_half: [T; 3],
}

impl<T: Real> Normalizer<T> {
    /// The padded (10%) bounding box of `vertices` (non-empty).
    pub fn from_vertices(vertices: &[[f32; 3]]) -> Self {
        let mut lo = [f32::MAX; 3];
        let mut hi = [f32::MIN; 3];
        for v in vertices {
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let centre = [0, 1, 2].map(|k| T::of(0.5 * (f64::from(lo[k]) + f64::from(hi[k]))));
        let inv_half = [0, 1, 2].map(|k| {
            let half = 0.5 * (f64::from(hi[k]) - f64::from(lo[k])) * 1.1;
            T::of(1.0 / half.max(1e-6))
        });
        Self { centre, inv_half }
    }

    pub(super) fn apply(&self, x: [T; 3]) -> [T; 3] {
        [0, 1, 2].map(|k| (x[k] - self.centre[k]) * self.inv_half[k])
    }
}

/// Frequency encoding of a normalised point into `out` (length [`ENC_DIM`]):
/// `[x, sin(2^k π x), cos(2^k π x)]_{k<L}`. Only octave 0 calls `sin_cos`; higher octaves use the
/// double-angle recurrence `sin 2a = 2 sin a cos a`, `cos 2a = (cos a − sin a)(cos a + sin a)`
/// (a few ulps from the direct evaluation after L − 1 = 3 doublings).
pub fn encode<T: Real>(xn: [T; 3], out: &mut [T]) {
    out[..3].copy_from_slice(&xn);
    let pi = T::of(std::f64::consts::PI);
    for c in 0..3 {
        let (mut s, mut co) = (pi * xn[c]).sin_cos();
        for k in 0..NUM_FREQS {
            out[3 + 6 * k + c] = s;
            out[3 + 6 * k + 3 + c] = co;
            let s2 = (s + s) * co;
            co = (co - s) * (co + s);
            s = s2;
        }
    }
}

/// Backward of [`encode`] from its output `enc` (the sines and cosines it holds are the derivatives'
/// ingredients, so no trigonometry is evaluated): `∂L/∂xn` from `∂L/∂encoding`.
pub fn encode_backward_from<T: Real>(enc: &[T], d_enc: &[T]) -> [T; 3] {
    let mut g = [d_enc[0], d_enc[1], d_enc[2]];
    let mut f = T::of(std::f64::consts::PI);
    for k in 0..NUM_FREQS {
        for c in 0..3 {
            let (s, co) = (enc[3 + 6 * k + c], enc[3 + 6 * k + 3 + c]);
            g[c] = g[c] + f * (co * d_enc[3 + 6 * k + c] - s * d_enc[3 + 6 * k + 3 + c]);
        }
        f = f + f;
    }
    g
}

/// Encodes the (box-normalised) `points` into `out` (`(N, ENC_DIM)`).
pub(super) fn encode_rows<T: Real>(norm: &Normalizer<T>, points: &[[T; 3]], out: &mut [T]) {
    for (p, row) in points.iter().zip(out.chunks_exact_mut(ENC_DIM)) {
        encode(norm.apply(*p), row);
    }
}

/// `∂L/∂points` (metres) of [`encode_rows`], written to `d_points`.
pub(super) fn encode_rows_backward<T: Real>(
    norm: &Normalizer<T>,
    enc: &[T],
    d_enc: &[T],
    d_points: &mut [[T; 3]],
) {
    for ((d, e), de) in d_points
        .iter_mut()
        .zip(enc.chunks_exact(ENC_DIM))
        .zip(d_enc.chunks_exact(ENC_DIM))
    {
        let g = encode_backward_from(e, de);
        *d = [0, 1, 2].map(|k| g[k] * norm.inv_half[k]);
    }
}
