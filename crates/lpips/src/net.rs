//! The LPIPS network: AlexNet trunk with its five ReLU taps, the per-pixel channel normalisation, the
//! 1×1 heads and the spatial mean (crate docs), forward and backward with respect to the first image.
//! Convolutions and pooling are `nn`'s; this module only wires them and must not read files.

use crate::LpipsError;
use nn::{
    conv2d_backward_input, conv2d_forward, max_pool2d_backward, max_pool2d_forward, Conv2dShape,
    MaxPool2dShape, Real,
};
use rand::{Rng, SeedableRng};

/// Output channels of the five AlexNet convolutions (= channels of the five taps).
pub const ALEXNET_CHANNELS: [usize; 5] = [64, 192, 384, 256, 256];
/// Kernel side of the five convolutions (pixels).
pub const KERNELS: [usize; 5] = [11, 5, 3, 3, 3];
/// Zero padding of the five convolutions (pixels per side).
pub const PADS: [usize; 5] = [2, 2, 1, 1, 1];
/// Stride of the first convolution (pixels); the others have stride 1.
pub const STEM_STRIDE: usize = 4;
/// Window side of the two max-pools (after taps 1 and 2), pixels.
pub const POOL_KERNEL: usize = 3;
/// Stride of the two max-pools, pixels.
pub const POOL_STRIDE: usize = 2;
/// The ScalingLayer's per-channel shift (RGB), applied to images mapped to [−1, 1].
pub const SHIFT: [f64; 3] = [-0.030, -0.088, -0.188];
/// The ScalingLayer's per-channel scale (RGB).
pub const SCALE: [f64; 3] = [0.458, 0.448, 0.450];
/// ε of the channel normalisation `f / (‖f‖₂ + ε)`.
pub const EPS: f64 = 1e-10;
/// Smallest image side (pixels) the network accepts; see [`tap_sizes`].
pub const MIN_SIZE: usize = 31;

/// (height, width) in pixels of the five taps for an image of `height` × `width` pixels, or `None`
/// when the image is too small for the network (a side below [`MIN_SIZE`]).
pub fn tap_sizes(height: usize, width: usize) -> Option<[(usize, usize); 5]> {
    let axis = |n: usize| -> Option<[usize; 3]> {
        let stem = (n + 2 * PADS[0]).checked_sub(KERNELS[0])? / STEM_STRIDE + 1;
        let pool = |m: usize| Some(m.checked_sub(POOL_KERNEL)? / POOL_STRIDE + 1);
        let first = pool(stem)?;
        Some([stem, first, pool(first)?])
    };
    let (h, w) = (axis(height)?, axis(width)?);
    Some([
        (h[0], w[0]),
        (h[1], w[1]),
        (h[2], w[2]),
        (h[2], w[2]),
        (h[2], w[2]),
    ])
}

/// An LPIPS network: the five convolutions of the trunk and the five heads, in precision `T`.
/// [`ALEXNET_CHANNELS`] for the real weights ([`crate::load_safetensors`]); tests may use fewer
/// channels with the same structure ([`Lpips::random`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Lpips<T> {
    channels: [usize; 5],
    weights: [Vec<T>; 5],
    biases: [Vec<T>; 5],
    heads: [Vec<T>; 5],
}

/// The normalised taps of one image, `f̂_l` as planar `(C_l, H_l, W_l)`: what the distance compares.
/// Computing them once lets a reference image be compared with many images.
#[derive(Clone, Debug, PartialEq)]
pub struct Features<T> {
    height: usize,
    width: usize,
    taps: [Vec<T>; 5],
}

impl<T> Features<T> {
    /// Height (pixels) of the image they were computed from.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Width (pixels) of the image they were computed from.
    pub fn width(&self) -> usize {
        self.width
    }
}

/// What the forward pass of one image keeps for its backward pass.
struct Trunk<T> {
    sizes: [(usize, usize); 5],
    /// The ReLU outputs `f_l`, planar `(C_l, H_l, W_l)`.
    taps: [Vec<T>; 5],
    /// Per tap and pixel, `‖f_l‖₂` over channels.
    norms: [Vec<T>; 5],
    /// The normalised taps.
    features: Features<T>,
    /// Positions of the maxima of the pools after taps 1 and 2.
    argmax: [Vec<u32>; 2],
}

impl<T: Real> Lpips<T> {
    /// A network from its parts: per convolution `i` its weight `(C_i, C_{i−1}, k_i, k_i)` (OIHW,
    /// `C_{−1} = 3`, `k_i` = [`KERNELS`]) and bias `(C_i)`, and per tap its head `(C_i)`, where the
    /// channel counts `C_i` are the heads' lengths. Lengths that do not fit are an error naming the
    /// part.
    pub fn from_parts(
        weights: [Vec<T>; 5],
        biases: [Vec<T>; 5],
        heads: [Vec<T>; 5],
    ) -> Result<Self, LpipsError> {
        let channels: [usize; 5] = std::array::from_fn(|i| heads[i].len());
        for i in 0..5 {
            let c_in = if i == 0 { 3 } else { channels[i - 1] };
            let want = channels[i] * c_in * KERNELS[i] * KERNELS[i];
            if channels[i] == 0 {
                return Err(LpipsError::Network(format!("lin{i}: empty head")));
            }
            if weights[i].len() != want {
                return Err(LpipsError::Network(format!(
                    "conv{i}.weight: expected {want} values ({} x {c_in} x {k} x {k}), got {}",
                    channels[i],
                    weights[i].len(),
                    k = KERNELS[i]
                )));
            }
            if biases[i].len() != channels[i] {
                return Err(LpipsError::Network(format!(
                    "conv{i}.bias: expected {} values, got {}",
                    channels[i],
                    biases[i].len()
                )));
            }
        }
        Ok(Self {
            channels,
            weights,
            biases,
            heads,
        })
    }

    /// A network with the given tap channels and random weights from `seed` (for tests): He-uniform
    /// convolution weights, biases in [−0.1, 0.1), non-negative heads in [0, 1).
    pub fn random(channels: [usize; 5], seed: u64) -> Self {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut draw = |n: usize, lo: f64, hi: f64| -> Vec<T> {
            (0..n).map(|_| T::of(rng.gen_range(lo..hi))).collect()
        };
        let mut weights: [Vec<T>; 5] = Default::default();
        let mut biases: [Vec<T>; 5] = Default::default();
        let mut heads: [Vec<T>; 5] = Default::default();
        for i in 0..5 {
            let c_in = if i == 0 { 3 } else { channels[i - 1] };
            let fan_in = c_in * KERNELS[i] * KERNELS[i];
            let bound = (6.0 / fan_in as f64).sqrt();
            weights[i] = draw(channels[i] * fan_in, -bound, bound);
            biases[i] = draw(channels[i], -0.1, 0.1);
            heads[i] = draw(channels[i], 0.0, 1.0);
        }
        Self {
            channels,
            weights,
            biases,
            heads,
        }
    }

    /// The same network in another precision (e.g. the f32 weights as f64 for a gradient check).
    pub fn cast<U: Real>(&self) -> Lpips<U> {
        let cast = |v: &Vec<T>| v.iter().map(|&x| U::of(x.as_f64())).collect::<Vec<U>>();
        Lpips {
            channels: self.channels,
            weights: self.weights.each_ref().map(cast),
            biases: self.biases.each_ref().map(cast),
            heads: self.heads.each_ref().map(cast),
        }
    }

    /// Channels of the five taps.
    pub fn channels(&self) -> [usize; 5] {
        self.channels
    }

    /// The normalised taps of `image` (planar `(3, height, width)`, values in [0, 1] as stored —
    /// see the crate docs).
    pub fn features(
        &self,
        image: &[T],
        height: usize,
        width: usize,
    ) -> Result<Features<T>, LpipsError> {
        Ok(self.trunk(image, height, width, None)?.features)
    }

    /// The LPIPS distance between two images of the same size (planar `(3, height, width)`,
    /// values in [0, 1] as stored). Symmetric up to rounding.
    pub fn distance(&self, a: &[T], b: &[T], height: usize, width: usize) -> Result<T, LpipsError> {
        let reference = self.features(b, height, width)?;
        self.distance_to(a, height, width, &reference)
    }

    /// The LPIPS distance between image `a` (planar `(3, height, width)`) and the image whose
    /// features `reference` holds; an error if their sizes differ.
    pub fn distance_to(
        &self,
        a: &[T],
        height: usize,
        width: usize,
        reference: &Features<T>,
    ) -> Result<T, LpipsError> {
        check_same_size(height, width, reference)?;
        let features = self.features(a, height, width)?;
        Ok(self.compare(&features, reference))
    }

    /// The distance of [`Lpips::distance_to`] and its gradient with respect to `a` (same layout as
    /// `a`); the reference is a constant.
    pub fn distance_and_gradient(
        &self,
        a: &[T],
        height: usize,
        width: usize,
        reference: &Features<T>,
    ) -> Result<(T, Vec<T>), LpipsError> {
        check_same_size(height, width, reference)?;
        let trunk = self.trunk(a, height, width, None)?;
        let value = self.compare(&trunk.features, reference);
        let gradient = self.backward(&trunk, reference, height, width)?;
        Ok((value, gradient))
    }

    /// `Σ_l mean_p Σ_c w_l[c] (a_l − b_l)²` over precomputed normalised taps of equal size: per pixel
    /// the channels in order, the pixels of a tap summed in order in f64.
    fn compare(&self, a: &Features<T>, b: &Features<T>) -> T {
        let mut total = 0.0f64;
        for l in 0..5 {
            let c = self.channels[l];
            let hw = a.taps[l].len() / c;
            let mut per_pixel = vec![T::zero(); hw];
            for (ch, &w) in self.heads[l].iter().enumerate() {
                let (pa, pb) = (
                    &a.taps[l][ch * hw..(ch + 1) * hw],
                    &b.taps[l][ch * hw..(ch + 1) * hw],
                );
                for ((s, &x), &y) in per_pixel.iter_mut().zip(pa).zip(pb) {
                    let d = x - y;
                    *s = *s + w * d * d;
                }
            }
            let sum: f64 = per_pixel.iter().map(|v| v.as_f64()).sum();
            total += sum / hw as f64;
        }
        T::of(total)
    }

    fn stem_shape(&self, height: usize, width: usize) -> Conv2dShape {
        Conv2dShape {
            batch: 1,
            c_in: 3,
            c_out: self.channels[0],
            height,
            width,
            kernel: KERNELS[0],
            stride: STEM_STRIDE,
            pad: PADS[0],
        }
    }

    /// Convolution `i ≥ 1`, whose input (and output) is `size`.
    fn conv_shape(&self, i: usize, size: (usize, usize)) -> Conv2dShape {
        Conv2dShape {
            batch: 1,
            c_in: self.channels[i - 1],
            c_out: self.channels[i],
            height: size.0,
            width: size.1,
            kernel: KERNELS[i],
            stride: 1,
            pad: PADS[i],
        }
    }

    /// The pool after tap `l ∈ {0, 1}`, whose input is `size`.
    fn pool_shape(&self, l: usize, size: (usize, usize)) -> MaxPool2dShape {
        MaxPool2dShape {
            planes: self.channels[l],
            height: size.0,
            width: size.1,
            kernel: POOL_KERNEL,
            stride: POOL_STRIDE,
        }
    }

    /// How far the forward pass of `image` is from the network's non-differentiable points: the
    /// smallest |pre-activation| of any ReLU and the smallest gap between the largest and the
    /// second-largest value of any max-pool window with a positive maximum (units of the
    /// activations). A finite-difference
    /// probe that moves no activation by this much crosses no kink (for gradient checks).
    pub fn kink_margin(&self, image: &[T], height: usize, width: usize) -> Result<T, LpipsError> {
        let mut margin = T::infinity();
        self.trunk(image, height, width, Some(&mut margin))?;
        Ok(margin)
    }

    /// The forward pass of one image, keeping what the backward needs; with `margin`, also lowers it
    /// to [`Lpips::kink_margin`]'s measure.
    fn trunk(
        &self,
        image: &[T],
        height: usize,
        width: usize,
        mut margin: Option<&mut T>,
    ) -> Result<Trunk<T>, LpipsError> {
        let hw = height * width;
        if image.len() != 3 * hw {
            return Err(LpipsError::ImageLength {
                expected: 3 * hw,
                actual: image.len(),
                height,
                width,
            });
        }
        let sizes = tap_sizes(height, width).ok_or(LpipsError::TooSmall {
            width,
            height,
            min: MIN_SIZE,
        })?;
        let mut x = vec![T::zero(); 3 * hw];
        for c in 0..3 {
            let (shift, scale) = (T::of(SHIFT[c]), T::of(SCALE[c]));
            for (o, &v) in x[c * hw..(c + 1) * hw]
                .iter_mut()
                .zip(&image[c * hw..(c + 1) * hw])
            {
                *o = (T::of(2.0) * v - T::one() - shift) / scale;
            }
        }
        let tap_len = |l: usize| self.channels[l] * sizes[l].0 * sizes[l].1;
        let mut taps: [Vec<T>; 5] = std::array::from_fn(|l| vec![T::zero(); tap_len(l)]);
        // Pool l reads tap l and has the size of tap l + 1.
        let mut argmax: [Vec<u32>; 2] =
            std::array::from_fn(|l| vec![0; self.channels[l] * sizes[l + 1].0 * sizes[l + 1].1]);
        conv2d_forward(
            self.stem_shape(height, width),
            &x,
            &self.weights[0],
            Some(&self.biases[0]),
            &mut taps[0],
        )?;
        relu(&mut taps[0], margin.as_deref_mut());
        for i in 1..5 {
            let (before, rest) = taps.split_at_mut(i);
            let pooled;
            let input: &[T] = if i <= 2 {
                let pool = self.pool_shape(i - 1, sizes[i - 1]);
                if let Some(m) = margin.as_deref_mut() {
                    *m = m.min(pool_gap(pool, &before[i - 1]));
                }
                let mut out = vec![T::zero(); pool.output_len()];
                max_pool2d_forward(pool, &before[i - 1], &mut out, &mut argmax[i - 1])?;
                pooled = out;
                &pooled
            } else {
                &before[i - 1]
            };
            conv2d_forward(
                self.conv_shape(i, sizes[i]),
                input,
                &self.weights[i],
                Some(&self.biases[i]),
                &mut rest[0],
            )?;
            relu(&mut rest[0], margin.as_deref_mut());
        }
        let mut norms: [Vec<T>; 5] = Default::default();
        let mut normalised: [Vec<T>; 5] = Default::default();
        for l in 0..5 {
            (normalised[l], norms[l]) = normalise(&taps[l], self.channels[l]);
        }
        Ok(Trunk {
            sizes,
            taps,
            norms,
            features: Features {
                height,
                width,
                taps: normalised,
            },
            argmax,
        })
    }

    /// ∂d/∂image for the forward pass `trunk` against `reference`.
    fn backward(
        &self,
        trunk: &Trunk<T>,
        reference: &Features<T>,
        height: usize,
        width: usize,
    ) -> Result<Vec<T>, LpipsError> {
        let sizes = trunk.sizes;
        // Per tap, ∂d/∂f_l: heads and spatial mean, then the normalisation.
        let d_taps: [Vec<T>; 5] = std::array::from_fn(|l| {
            let c = self.channels[l];
            let hw = sizes[l].0 * sizes[l].1;
            let scale = T::of(2.0 / hw as f64);
            let (a, b) = (&trunk.features.taps[l], &reference.taps[l]);
            let mut d_normalised = vec![T::zero(); c * hw];
            for (ch, &w) in self.heads[l].iter().enumerate() {
                let k = scale * w;
                for p in ch * hw..(ch + 1) * hw {
                    d_normalised[p] = k * (a[p] - b[p]);
                }
            }
            normalise_backward(&trunk.taps[l], &trunk.norms[l], &d_normalised, c)
        });
        // Down the trunk: taps 5 → 1, each tap's cotangent added before its ReLU.
        let mut g = d_taps[4].clone();
        for i in (1..5).rev() {
            relu_mask(&mut g, &trunk.taps[i]);
            let conv = self.conv_shape(i, sizes[i]);
            let mut d_input = vec![T::zero(); conv.input_len()];
            conv2d_backward_input(conv, &g, &self.weights[i], &mut d_input)?;
            g = if i <= 2 {
                let pool = self.pool_shape(i - 1, sizes[i - 1]);
                let mut d_tap = vec![T::zero(); pool.input_len()];
                max_pool2d_backward(pool, &trunk.argmax[i - 1], &d_input, &mut d_tap)?;
                d_tap
            } else {
                d_input
            };
            for (o, &v) in g.iter_mut().zip(&d_taps[i - 1]) {
                *o = *o + v;
            }
        }
        relu_mask(&mut g, &trunk.taps[0]);
        let mut d_x = vec![T::zero(); 3 * height * width];
        conv2d_backward_input(
            self.stem_shape(height, width),
            &g,
            &self.weights[0],
            &mut d_x,
        )?;
        let hw = height * width;
        for c in 0..3 {
            let k = T::of(2.0 / SCALE[c]);
            for v in &mut d_x[c * hw..(c + 1) * hw] {
                *v = *v * k;
            }
        }
        Ok(d_x)
    }
}

/// Refuses `height × width` against the size `reference` was computed at.
fn check_same_size<T>(
    height: usize,
    width: usize,
    reference: &Features<T>,
) -> Result<(), LpipsError> {
    if (height, width) != (reference.height, reference.width) {
        return Err(LpipsError::SizeMismatch {
            a_width: width,
            a_height: height,
            b_width: reference.width,
            b_height: reference.height,
        });
    }
    Ok(())
}

/// `x = max(x, 0)` in place; with `margin`, lowers it to the smallest |x| seen.
fn relu<T: Real>(x: &mut [T], margin: Option<&mut T>) {
    if let Some(m) = margin {
        *m = x.iter().fold(*m, |acc, v| acc.min(v.abs()));
    }
    for v in x {
        *v = v.max(T::zero());
    }
}

/// The smallest gap between the largest and second-largest value of any window of `pool` on the
/// ReLU output `input` whose maximum is positive (0 on a tie).
fn pool_gap<T: Real>(pool: MaxPool2dShape, input: &[T]) -> T {
    let (h, w) = (pool.height, pool.width);
    let (k, s) = (pool.kernel, pool.stride);
    let mut gap = T::infinity();
    for plane in input.chunks_exact(h * w) {
        for y in 0..pool.out_height() {
            for x in 0..pool.out_width() {
                let (mut first, mut second) = (T::neg_infinity(), T::neg_infinity());
                for iy in y * s..y * s + k {
                    for &v in &plane[iy * w + x * s..iy * w + x * s + k] {
                        if v > first {
                            (first, second) = (v, first);
                        } else if v > second {
                            second = v;
                        }
                    }
                }
                // A window whose maximum is a ReLU's 0 stays 0 under any probe the ReLU margin
                // allows, ties or not.
                if first > T::zero() {
                    gap = gap.min(first - second);
                }
            }
        }
    }
    gap
}

/// `g = 0` where the ReLU output `f` is not positive (the derivative at the kink is 0, as PyTorch).
fn relu_mask<T: Real>(g: &mut [T], f: &[T]) {
    for (o, &v) in g.iter_mut().zip(f) {
        if v <= T::zero() {
            *o = T::zero();
        }
    }
}

/// Per pixel of planar `(c, H, W)` `f`: `(f / (r + ε), r)` with `r = ‖f‖₂` over channels (summed in
/// channel order).
fn normalise<T: Real>(f: &[T], c: usize) -> (Vec<T>, Vec<T>) {
    let hw = f.len() / c;
    let mut r2 = vec![T::zero(); hw];
    for plane in f.chunks_exact(hw) {
        for (s, &v) in r2.iter_mut().zip(plane) {
            *s = *s + v * v;
        }
    }
    let norms: Vec<T> = r2.iter().map(|v| v.sqrt()).collect();
    let inv: Vec<T> = norms.iter().map(|&r| T::one() / (r + T::of(EPS))).collect();
    let mut out = vec![T::zero(); f.len()];
    for (dst, src) in out.chunks_exact_mut(hw).zip(f.chunks_exact(hw)) {
        for ((o, &v), &k) in dst.iter_mut().zip(src).zip(&inv) {
            *o = v * k;
        }
    }
    (out, norms)
}

/// Backward of [`normalise`]: `∂/∂f = g / (r + ε) − f · ⟨g, f⟩ / (r (r + ε)²)` per pixel, the second
/// term dropped where `r = 0` (then `f = 0` too).
fn normalise_backward<T: Real>(f: &[T], norms: &[T], g: &[T], c: usize) -> Vec<T> {
    let hw = f.len() / c;
    let mut dot = vec![T::zero(); hw];
    for (gp, fp) in g.chunks_exact(hw).zip(f.chunks_exact(hw)) {
        for ((s, &a), &b) in dot.iter_mut().zip(gp).zip(fp) {
            *s = *s + a * b;
        }
    }
    let eps = T::of(EPS);
    let inv: Vec<T> = norms.iter().map(|&r| T::one() / (r + eps)).collect();
    let coef: Vec<T> = norms
        .iter()
        .zip(&dot)
        .map(|(&r, &d)| {
            if r > T::zero() {
                d / (r * (r + eps) * (r + eps))
            } else {
                T::zero()
            }
        })
        .collect();
    let mut out = vec![T::zero(); f.len()];
    for ((dst, gp), fp) in out
        .chunks_exact_mut(hw)
        .zip(g.chunks_exact(hw))
        .zip(f.chunks_exact(hw))
    {
        for p in 0..hw {
            dst[p] = gp[p] * inv[p] - fp[p] * coef[p];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tap_sizes_at_256_and_the_minimum() {
        assert_eq!(
            tap_sizes(256, 256),
            Some([(63, 63), (31, 31), (15, 15), (15, 15), (15, 15)])
        );
        assert_eq!(
            tap_sizes(MIN_SIZE, MIN_SIZE + 9),
            Some([(7, 9), (3, 4), (1, 1), (1, 1), (1, 1)])
        );
        assert_eq!(tap_sizes(MIN_SIZE - 1, 256), None);
        assert_eq!(tap_sizes(256, MIN_SIZE - 1), None);
    }

    #[test]
    fn normalise_backward_matches_a_hand_derivative() {
        // One pixel, two channels: n = f / (|f| + ε); dn/df from the closed form.
        let f = [3.0f64, 4.0];
        let (n, r) = normalise(&f, 2);
        assert!((n[0] - 0.6).abs() < 1e-9 && (n[1] - 0.8).abs() < 1e-9 && r[0] == 5.0);
        let g = [1.0, 0.0];
        let d = normalise_backward(&f, &r, &g, 2);
        // ∂n0/∂f0 = 1/5 − 9/125, ∂n0/∂f1 = −12/125.
        assert!((d[0] - (0.2 - 9.0 / 125.0)).abs() < 1e-9, "{d:?}");
        assert!((d[1] + 12.0 / 125.0).abs() < 1e-9, "{d:?}");
        let zero = normalise_backward(&[0.0, 0.0], &[0.0], &g, 2);
        assert!(zero.iter().all(|v| v.is_finite()));
    }
}
