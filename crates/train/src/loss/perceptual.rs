//! LPIPS on the project's images: the evaluation metric and the optional perceptual training term
//! (3DGS-Avatar's third loss; `lpips_weight`), generic over f32 / f64 (the trainer and the metrics run
//! f32, the gradient check f64).
//!
//! The project's images are linear intensities (DESIGN.md §3; the benchmark's PNGs store them
//! sRGB-encoded and `scene` decodes them). LPIPS was trained on sRGB-encoded images, so every image is
//! **sRGB-encoded before the network** ([`srgb_encode`]: the same transfer function as
//! `scene::image_io::srgb_from_linear`, values clamped to [0, 1]) — the distance of two frames is then
//! that of their PNGs, which `cargo xtask lpips` reads as stored. The loss's gradient passes back
//! through the encoding (zero outside [0, 1], where it clamps).
//!
//! The network is `lpips::Lpips` (AlexNet, v0.1); this module must not load weights (the driver
//! resolves the shipped file and hands the network over).

use crate::TrainError;
use lpips::{Features, Lpips};
use nn::Real;

/// The sRGB transfer function (IEC 61966-2-1) of a linear intensity, clamped to [0, 1] first:
/// `12.92·x` up to 0.0031308, `1.055·x^(1/2.4) − 0.055` above.
pub fn srgb_encode<T: Real>(x: T) -> T {
    let x = x.max(T::zero()).min(T::one());
    if x <= T::of(0.003_130_8) {
        T::of(12.92) * x
    } else {
        T::of(1.055) * x.powf(T::of(1.0 / 2.4)) - T::of(0.055)
    }
}

/// d[`srgb_encode`]/dx: 0 outside (0, 1) (the clamp; also at the bounds themselves), 12.92 on the
/// linear segment, `1.055 / 2.4 · x^(1/2.4 − 1)` above it.
pub fn srgb_encode_derivative<T: Real>(x: T) -> T {
    if x <= T::zero() || x >= T::one() {
        T::zero()
    } else if x <= T::of(0.003_130_8) {
        T::of(12.92)
    } else {
        T::of(1.055 / 2.4) * x.powf(T::of(1.0 / 2.4 - 1.0))
    }
}

/// [`srgb_encode`] of every value.
pub fn srgb_image<T: Real>(linear: &[T]) -> Vec<T> {
    linear.iter().map(|&v| srgb_encode(v)).collect()
}

/// The LPIPS features of a linear planar (3, H, W) image (sRGB-encoded first): the reference side of
/// [`lpips_distance`] and [`lpips_loss`], computed once per reference.
pub fn reference_features<T: Real>(
    net: &Lpips<T>,
    linear: &[T],
    height: usize,
    width: usize,
) -> Result<Features<T>, TrainError> {
    Ok(net.features(&srgb_image(linear), height, width)?)
}

/// LPIPS between a linear planar (3, H, W) image and a reference's features.
pub fn lpips_distance<T: Real>(
    net: &Lpips<T>,
    linear: &[T],
    height: usize,
    width: usize,
    reference: &Features<T>,
) -> Result<T, TrainError> {
    Ok(net.distance_to(&srgb_image(linear), height, width, reference)?)
}

/// The perceptual loss of a linear planar (3, H, W) prediction against a reference's features:
/// LPIPS and its gradient with respect to the (linear) prediction.
pub fn lpips_loss<T: Real>(
    net: &Lpips<T>,
    prediction: &[T],
    height: usize,
    width: usize,
    reference: &Features<T>,
) -> Result<(T, Vec<T>), TrainError> {
    let (value, d_encoded) =
        net.distance_and_gradient(&srgb_image(prediction), height, width, reference)?;
    let gradient = d_encoded
        .iter()
        .zip(prediction)
        .map(|(&g, &x)| g * srgb_encode_derivative(x))
        .collect();
    Ok((value, gradient))
}

/// The perceptual training term of one frame: `weight · LPIPS(prediction, observed)` with
/// `prediction` the mean of the frame's S renders (linear planar (3, H, W)), its cotangent added to
/// every render's `d_renders[s]` (whose first 3·H·W values are its RGB planes) scaled like the
/// photometric loss's: by `weight / S`, or `weight` for one render. With `grey` (grey frames),
/// `prediction` is the luminance of the mean render, as [`crate::loss::photometric::exposure_loss`]
/// returns it, and the cotangent goes back through [`crate::loss::image::luminance3`]. Returns the
/// weighted value.
pub fn perceptual_term<T: Real>(
    net: &Lpips<T>,
    prediction: &[T],
    observed: &[T],
    height: usize,
    width: usize,
    weight: T,
    d_renders: &mut [Vec<T>],
    grey: bool,
) -> Result<T, TrainError> {
    let reference = reference_features(net, observed, height, width)?;
    let (value, mut d_prediction) = lpips_loss(net, prediction, height, width, &reference)?;
    if grey {
        d_prediction = crate::loss::image::luminance3_backward(&d_prediction, height * width);
    }
    let share = match d_renders.len() {
        1 => weight,
        s => weight * (T::one() / T::of(s as f64)),
    };
    for d in d_renders.iter_mut() {
        if d.len() < d_prediction.len() {
            return Err(TrainError::Shape {
                what: "perceptual term: a render's cotangent".into(),
                expected: d_prediction.len(),
                found: d.len(),
            });
        }
        crate::loss::photometric::add_scaled(&mut d[..d_prediction.len()], &d_prediction, share);
    }
    Ok(weight * value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_matches_the_scene_crate_and_its_derivative_its_differences() {
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            let ours = srgb_encode(x);
            let scene = scene::image_io::srgb_from_linear(x);
            assert!((ours - scene).abs() <= 2e-7, "{x}: {ours} vs {scene}");
        }
        for &x in &[0.001f64, 0.002, 0.01, 0.2, 0.5, 0.9] {
            let h = 1e-7;
            let numeric = (srgb_encode(x + h) - srgb_encode(x - h)) / (2.0 * h);
            let analytic = srgb_encode_derivative(x);
            assert!((numeric - analytic).abs() < 1e-6 * analytic, "{x}");
        }
        assert_eq!(srgb_encode(-0.5f64), 0.0);
        assert!((srgb_encode(1.5f64) - 1.0).abs() < 1e-15);
        assert_eq!(srgb_encode_derivative(1.5f64), 0.0);
    }
}
