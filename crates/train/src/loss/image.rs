//! Image-space losses with their analytic backward: L1 and SSIM / D-SSIM (11×11 Gaussian window,
//! σ = 1.5, zero padding, C1 = 0.01², C2 = 0.03², as in the 3DGS training code). The metrics built
//! on them (PSNR, mask IoU) are in `eval`.
//!
//! Images are planar (C, H, W) linear values with data range 1. The SSIM here is the one the loss
//! optimises and the one the metrics report; it is the 3DGS variant
//! (zero-padded "same" convolution, mean over every pixel), not skimage's valid-region variant.
//! Everything is generic over [`num_traits::Float`] so the f64 instantiation can be finite-difference
//! checked; parallel work splits by channel and reduces in a fixed order (bit-identical for any thread
//! count).

use num_traits::Float;
use rayon::prelude::*;

/// SSIM window side (pixels).
pub const SSIM_WINDOW: usize = 11;
/// SSIM Gaussian window standard deviation (pixels).
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM stabiliser C1 = (0.01 · data range)².
pub const SSIM_C1: f64 = 0.01 * 0.01;
/// SSIM stabiliser C2 = (0.03 · data range)².
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// Shape of a planar image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageShape {
    /// Channels.
    pub channels: usize,
    /// Height in pixels.
    pub height: usize,
    /// Width in pixels.
    pub width: usize,
}

impl ImageShape {
    /// Number of values, C·H·W.
    pub fn len(&self) -> usize {
        self.channels * self.height * self.width
    }

    /// True for an image with no pixel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Normalised 1D Gaussian window of [`SSIM_WINDOW`] taps with σ = [`SSIM_SIGMA`].
pub fn gaussian_window<T: Float>() -> [T; SSIM_WINDOW] {
    let half = (SSIM_WINDOW / 2) as f64;
    let w: Vec<f64> = (0..SSIM_WINDOW)
        .map(|i| (-((i as f64 - half).powi(2)) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp())
        .collect();
    let sum: f64 = w.iter().sum();
    std::array::from_fn(|i| T::from(w[i] / sum).unwrap_or_else(T::zero))
}

/// Separable "same" correlation of one (H, W) plane with the Gaussian window, zero padding.
/// The window is symmetric, so this operator is its own transpose (used by the backward pass).
///
/// Every output is the sum of its in-range taps in increasing tap order, starting from zero; the
/// horizontal pass reads a zero-padded copy of the row (an out-of-range tap adds an exact +0) and the
/// vertical pass accumulates whole rows tap by tap, so both loops run over contiguous memory and
/// vectorise while each value is the same sum, in the same order, as the direct loops.
fn blur_plane<T: Float>(
    src: &[T],
    dst: &mut [T],
    tmp: &mut [T],
    h: usize,
    w: usize,
    k: &[T; SSIM_WINDOW],
) {
    let r = SSIM_WINDOW / 2;
    let mut padded = vec![T::zero(); w + 2 * r];
    for y in 0..h {
        padded[r..r + w].copy_from_slice(&src[y * w..(y + 1) * w]);
        let out = &mut tmp[y * w..(y + 1) * w];
        out.iter_mut().for_each(|v| *v = T::zero());
        for (j, &kj) in k.iter().enumerate() {
            for (o, &p) in out.iter_mut().zip(&padded[j..j + w]) {
                *o = *o + kj * p;
            }
        }
    }
    for y in 0..h {
        let lo = y.saturating_sub(r);
        let hi = (y + r).min(h - 1);
        let out = &mut dst[y * w..(y + 1) * w];
        out.iter_mut().for_each(|v| *v = T::zero());
        for yy in lo..=hi {
            let kj = k[yy + r - y];
            for (o, &t) in out.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *o = *o + kj * t;
            }
        }
    }
}

/// Mean absolute error over all values, and (if `grad` is given) its gradient w.r.t. `pred` written
/// into `grad` (sign(pred − target)/N; 0 where equal).
pub fn l1<T: Float + Send + Sync>(pred: &[T], target: &[T], grad: Option<&mut [T]>) -> T {
    let n = T::from(pred.len().max(1)).unwrap_or_else(T::one);
    let sum = pred
        .iter()
        .zip(target)
        .fold(T::zero(), |acc, (&p, &t)| acc + (p - t).abs());
    if let Some(g) = grad {
        for ((g, &p), &t) in g.iter_mut().zip(pred).zip(target) {
            let d = p - t;
            *g = super::l1_slope(d, T::one() / n);
        }
    }
    sum / n
}

/// Per-channel blurred statistics kept from the forward pass for the backward.
struct SsimStats<T> {
    mu_x: Vec<T>,
    mu_y: Vec<T>,
    sigma_x: Vec<T>,
    sigma_y: Vec<T>,
    sigma_xy: Vec<T>,
}

fn ssim_stats<T: Float + Send + Sync>(x: &[T], y: &[T], h: usize, w: usize) -> SsimStats<T> {
    let k = gaussian_window::<T>();
    let n = h * w;
    let mut tmp = vec![T::zero(); n];
    let mut blur = |src: &[T]| {
        let mut out = vec![T::zero(); n];
        blur_plane(src, &mut out, &mut tmp, h, w, &k);
        out
    };
    let mu_x = blur(x);
    let mu_y = blur(y);
    let xx: Vec<T> = x.iter().map(|&v| v * v).collect();
    let yy: Vec<T> = y.iter().map(|&v| v * v).collect();
    let xy: Vec<T> = x.iter().zip(y).map(|(&a, &b)| a * b).collect();
    let e_xx = blur(&xx);
    let e_yy = blur(&yy);
    let e_xy = blur(&xy);
    let sigma_x = (0..n).map(|i| e_xx[i] - mu_x[i] * mu_x[i]).collect();
    let sigma_y = (0..n).map(|i| e_yy[i] - mu_y[i] * mu_y[i]).collect();
    let sigma_xy = (0..n).map(|i| e_xy[i] - mu_x[i] * mu_y[i]).collect();
    SsimStats {
        mu_x,
        mu_y,
        sigma_x,
        sigma_y,
        sigma_xy,
    }
}

/// Mean SSIM between `target` (x) and `pred` (y), both (C, H, W); if `grad` is given, writes
/// dSSIM/d`pred` into it (same layout). D-SSIM for a loss is `1 − ssim`, whose gradient is `−grad`.
pub fn ssim<T: Float + Send + Sync>(
    pred: &[T],
    target: &[T],
    shape: ImageShape,
    grad: Option<&mut [T]>,
) -> T {
    let (h, w) = (shape.height, shape.width);
    let plane = h * w;
    if plane == 0 || shape.channels == 0 {
        return T::one();
    }
    let c1 = T::from(SSIM_C1).unwrap_or_else(T::zero);
    let c2 = T::from(SSIM_C2).unwrap_or_else(T::zero);
    let two = T::one() + T::one();
    let total = T::from(shape.len()).unwrap_or_else(T::one);
    let want_grad = grad.is_some();
    // One task per channel; each returns its SSIM sum and (optionally) its gradient plane.
    let per_channel: Vec<(T, Vec<T>)> = (0..shape.channels)
        .into_par_iter()
        .map(|c| {
            let x = &target[c * plane..(c + 1) * plane];
            let y = &pred[c * plane..(c + 1) * plane];
            let s = ssim_stats(x, y, h, w);
            let mut sum = T::zero();
            let (mut d_mu, mut d_e_yy, mut d_e_xy) = if want_grad {
                (
                    vec![T::zero(); plane],
                    vec![T::zero(); plane],
                    vec![T::zero(); plane],
                )
            } else {
                (Vec::new(), Vec::new(), Vec::new())
            };
            for i in 0..plane {
                let (mx, my) = (s.mu_x[i], s.mu_y[i]);
                let a1 = two * mx * my + c1;
                let a2 = two * s.sigma_xy[i] + c2;
                let b1 = mx * mx + my * my + c1;
                let b2 = s.sigma_x[i] + s.sigma_y[i] + c2;
                let value = a1 * a2 / (b1 * b2);
                sum = sum + value;
                if want_grad {
                    // Partial derivatives of the SSIM map w.r.t. (μy, σy², σxy), then through
                    // σy² = E[y²] − μy² and σxy = E[xy] − μx μy; scaled by 1/N for the mean.
                    let d_sxy = two * a1 / (b1 * b2);
                    let d_sy = -a1 * a2 / (b1 * b2 * b2);
                    let d_my = two * mx * a2 / (b1 * b2) - value * two * my / b1;
                    d_mu[i] = (d_my - two * my * d_sy - mx * d_sxy) / total;
                    d_e_yy[i] = d_sy / total;
                    d_e_xy[i] = d_sxy / total;
                }
            }
            let mut g = Vec::new();
            if want_grad {
                // Back through the (self-adjoint) blur: dy = G*dμ + 2y·G*dE[y²] + x·G*dE[xy].
                let k = gaussian_window::<T>();
                let mut tmp = vec![T::zero(); plane];
                let mut b_mu = vec![T::zero(); plane];
                let mut b_yy = vec![T::zero(); plane];
                let mut b_xy = vec![T::zero(); plane];
                blur_plane(&d_mu, &mut b_mu, &mut tmp, h, w, &k);
                blur_plane(&d_e_yy, &mut b_yy, &mut tmp, h, w, &k);
                blur_plane(&d_e_xy, &mut b_xy, &mut tmp, h, w, &k);
                g = (0..plane)
                    .map(|i| b_mu[i] + two * y[i] * b_yy[i] + x[i] * b_xy[i])
                    .collect();
            }
            (sum, g)
        })
        .collect();
    if let Some(grad) = grad {
        for (c, (_, g)) in per_channel.iter().enumerate() {
            grad[c * plane..(c + 1) * plane].copy_from_slice(g);
        }
    }
    per_channel.iter().fold(T::zero(), |acc, (s, _)| acc + *s) / total
}

/// Crops a planar (C, H, W) image to rows `y0..y1`, columns `x0..x1`.
pub fn crop(
    image: &[f32],
    shape: ImageShape,
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
) -> Vec<f32> {
    let mut out = Vec::with_capacity(shape.channels * (y1 - y0) * (x1 - x0));
    for c in 0..shape.channels {
        for y in y0..y1 {
            let row = (c * shape.height + y) * shape.width;
            out.extend_from_slice(&image[row + x0..row + x1]);
        }
    }
    out
}

/// Grey frames (`images.channels = 1`, held in memory as three equal planes): the Rec. 601
/// luminance `Y = 0.299 R + 0.587 G + 0.114 B` of planar linear RGB `(3, hw)`, written to all
/// three planes, so a colour render compares with a grey frame plane by plane.
pub fn luminance3<T: Float>(rgb: &[T], hw: usize) -> Vec<T> {
    let w = scene::image_io::REC601_LUMA.map(|v| T::from(v).unwrap_or_else(T::zero));
    let mut out = vec![T::zero(); 3 * hw];
    for i in 0..hw {
        let y = w[0] * rgb[i] + w[1] * rgb[hw + i] + w[2] * rgb[2 * hw + i];
        for c in 0..3 {
            out[c * hw + i] = y;
        }
    }
    out
}

/// The adjoint of [`luminance3`]: `∂L/∂rgb_c = w_c · Σ_c' ∂L/∂out_c'` per pixel. Planes of
/// `grad` past the third are returned unchanged.
pub fn luminance3_backward<T: Float>(grad: &[T], hw: usize) -> Vec<T> {
    let w = scene::image_io::REC601_LUMA.map(|v| T::from(v).unwrap_or_else(T::zero));
    let mut out = grad.to_vec();
    for i in 0..hw {
        let s = grad[i] + grad[hw + i] + grad[2 * hw + i];
        for c in 0..3 {
            out[c * hw + i] = w[c] * s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Slow oracle: SSIM with a direct 2D window sum and explicit zero padding.
    /// The direct loops `blur_plane` replaced (per output, in-range taps in increasing order).
    fn blur_plane_direct(src: &[f32], h: usize, w: usize) -> Vec<f32> {
        let k = gaussian_window::<f32>();
        let r = SSIM_WINDOW / 2;
        let mut tmp = vec![0.0f32; h * w];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0f32;
                for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                    acc += k[xx + r - x] * src[y * w + xx];
                }
                tmp[y * w + x] = acc;
            }
        }
        let mut dst = vec![0.0f32; h * w];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0f32;
                for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                    acc += k[yy + r - y] * tmp[yy * w + x];
                }
                dst[y * w + x] = acc;
            }
        }
        dst
    }

    #[test]
    fn blur_is_bit_identical_to_the_direct_loops() {
        for (h, w) in [(1, 1), (3, 17), (23, 5), (40, 33)] {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64((h * 100 + w) as u64);
            let src: Vec<f32> = (0..h * w).map(|_| rng.gen_range(-0.3..0.7)).collect();
            let (mut dst, mut tmp) = (vec![0.0f32; h * w], vec![0.0f32; h * w]);
            blur_plane(&src, &mut dst, &mut tmp, h, w, &gaussian_window::<f32>());
            let direct = blur_plane_direct(&src, h, w);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&dst), bits(&direct), "{h}x{w}");
        }
    }

    fn naive_ssim(pred: &[f64], target: &[f64], shape: ImageShape) -> f64 {
        let k = gaussian_window::<f64>();
        let r = (SSIM_WINDOW / 2) as isize;
        let (h, w) = (shape.height as isize, shape.width as isize);
        let mut total = 0.0;
        for c in 0..shape.channels {
            let at = |img: &[f64], y: isize, x: isize| {
                if y < 0 || x < 0 || y >= h || x >= w {
                    0.0
                } else {
                    img[c * shape.height * shape.width + (y * w + x) as usize]
                }
            };
            for y in 0..h {
                for x in 0..w {
                    let (mut mx, mut my, mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for dy in -r..=r {
                        for dx in -r..=r {
                            let wgt = k[(dy + r) as usize] * k[(dx + r) as usize];
                            let a = at(target, y + dy, x + dx);
                            let b = at(pred, y + dy, x + dx);
                            mx += wgt * a;
                            my += wgt * b;
                            xx += wgt * a * a;
                            yy += wgt * b * b;
                            xy += wgt * a * b;
                        }
                    }
                    let (sx, sy, sxy) = (xx - mx * mx, yy - my * my, xy - mx * my);
                    total += (2.0 * mx * my + SSIM_C1) * (2.0 * sxy + SSIM_C2)
                        / ((mx * mx + my * my + SSIM_C1) * (sx + sy + SSIM_C2));
                }
            }
        }
        total / shape.len() as f64
    }

    #[test]
    fn ssim_matches_the_naive_oracle_and_is_one_for_identical_images() {
        let shape = ImageShape {
            channels: 2,
            height: 20,
            width: 17,
        };
        let img: Vec<f64> = (0..shape.len())
            .map(|i| 0.5 + 0.3 * (i as f64 / 10.0).sin())
            .collect();
        assert!((ssim(&img, &img, shape, None) - 1.0).abs() < 1e-12);
        let noisy: Vec<f64> = img
            .iter()
            .enumerate()
            .map(|(i, v)| v + if (i * 7919) % 3 == 0 { 0.2 } else { -0.1 })
            .collect();
        let fast = ssim(&noisy, &img, shape, None);
        let slow = naive_ssim(&noisy, &img, shape);
        assert!((fast - slow).abs() < 1e-12, "{fast} vs {slow}");
        assert!(fast < 0.9, "{fast}");
    }

    #[test]
    fn window_is_normalised_and_symmetric() {
        let k = gaussian_window::<f64>();
        assert!((k.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        for i in 0..SSIM_WINDOW {
            assert_eq!(k[i], k[SSIM_WINDOW - 1 - i]);
        }
    }

    #[test]
    fn crop_takes_the_right_window() {
        let shape = ImageShape {
            channels: 2,
            height: 3,
            width: 4,
        };
        let img: Vec<f32> = (0..24).map(|v| v as f32).collect();
        assert_eq!(
            crop(&img, shape, 1, 1, 3, 3),
            vec![5.0, 6.0, 9.0, 10.0, 17.0, 18.0, 21.0, 22.0]
        );
    }
}
