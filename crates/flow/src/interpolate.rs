//! In-between frames from optical flow (the linear flow approximation of Super SloMo, without its
//! refinement network): with `F₀₁`, `F₁₀` the flows between frames 0 and 1 (pixels, `x + F(x)`),
//! the flows from an in-between time `t ∈ (0, 1)` back to the two frames are approximated by
//!
//! ```text
//! F_t0 = −(1 − t) t F₀₁ + t² F₁₀,    F_t1 = (1 − t)² F₀₁ − t (1 − t) F₁₀,
//! ```
//!
//! and the frame is `I_t = (1 − t) · I₀(x + F_t0(x)) + t · I₁(x + F_t1(x))` (bilinear sampling,
//! border clamped). What the paper did for ZJU-MoCap-Blur before averaging frames into a blur; as
//! good as the flows it is given.

use crate::{FlowError, SpyNet};

/// The two flows between `a` and `b` (planar RGB `(3, h, w)` in `[0, 1]`), `(F_ab, F_ba)`, each
/// `(2, h, w)` pixels, from `net`.
pub fn flows_between(
    net: &SpyNet<f32>,
    a: &[f32],
    b: &[f32],
    h: usize,
    w: usize,
) -> Result<(Vec<f32>, Vec<f32>), FlowError> {
    let ab = net.forward(a, b, h, w)?.flow;
    let ba = net.forward(b, a, h, w)?.flow;
    Ok((ab, ba))
}

/// The frame at `t ∈ (0, 1)` between `a` (t = 0) and `b` (t = 1), planar `(channels, h, w)`,
/// from the flows `(F_ab, F_ba)` of [`flows_between`] (module documentation for the formula).
pub fn frame_between(
    a: &[f32],
    b: &[f32],
    (f_ab, f_ba): (&[f32], &[f32]),
    channels: usize,
    h: usize,
    w: usize,
    t: f32,
) -> Result<Vec<f32>, FlowError> {
    let n = channels * h * w;
    if a.len() != n || b.len() != n || f_ab.len() != 2 * h * w || f_ba.len() != 2 * h * w {
        return Err(FlowError::Size(format!(
            "frame_between: {channels}x{h}x{w} frames and (2, {h}, {w}) flows expected, got {} / {} values and {} / {} flow values",
            a.len(),
            b.len(),
            f_ab.len(),
            f_ba.len()
        )));
    }
    let f_t0: Vec<f32> = f_ab
        .iter()
        .zip(f_ba)
        .map(|(&p, &q)| -(1.0 - t) * t * p + t * t * q)
        .collect();
    let f_t1: Vec<f32> = f_ab
        .iter()
        .zip(f_ba)
        .map(|(&p, &q)| (1.0 - t) * (1.0 - t) * p - t * (1.0 - t) * q)
        .collect();
    let (mut from_a, mut from_b) = (vec![0.0f32; n], vec![0.0f32; n]);
    nn::warp_forward(1, channels, h, w, a, &f_t0, &mut from_a)?;
    nn::warp_forward(1, channels, h, w, b, &f_t1, &mut from_b)?;
    Ok(from_a
        .iter()
        .zip(&from_b)
        .map(|(&x, &y)| (1.0 - t) * x + t * y)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth pattern shifted by `dx` pixels to the right.
    fn pattern(h: usize, w: usize, dx: f32) -> Vec<f32> {
        (0..h * w)
            .map(|p| {
                let (y, x) = ((p / w) as f32, (p % w) as f32 - dx);
                0.5 + 0.4 * (0.3 * x).sin() * (0.2 * y).cos()
            })
            .collect()
    }

    #[test]
    fn a_translation_is_interpolated_half_way_with_the_true_flows() {
        let (h, w) = (16, 32);
        let (a, b) = (pattern(h, w, 0.0), pattern(h, w, 6.0));
        // True flows: a at x matches b at x + 6; b at x matches a at x − 6.
        let f_ab: Vec<f32> = (0..2 * h * w)
            .map(|i| if i < h * w { 6.0 } else { 0.0 })
            .collect();
        let f_ba: Vec<f32> = f_ab.iter().map(|v| -v).collect();
        let mid = frame_between(&a, &b, (&f_ab, &f_ba), 1, h, w, 0.5).expect("sizes");
        let truth = pattern(h, w, 3.0);
        // Away from the borders (clamped samples), the in-between is the pattern shifted by 3 px.
        for y in 0..h {
            for x in 7..w - 7 {
                let p = y * w + x;
                assert!(
                    (mid[p] - truth[p]).abs() < 1e-5,
                    "({x}, {y}): {} vs {}",
                    mid[p],
                    truth[p]
                );
            }
        }
        // Without the flows the average is a double image, not the shifted pattern.
        let zero = vec![0.0f32; 2 * h * w];
        let blend = frame_between(&a, &b, (&zero, &zero), 1, h, w, 0.5).expect("sizes");
        let err = (0..h * w)
            .map(|p| (blend[p] - truth[p]).abs())
            .fold(0.0f32, f32::max);
        assert!(err > 0.05, "{err}");
        assert!(frame_between(&a, &b[1..], (&f_ab, &f_ba), 1, h, w, 0.5).is_err());
    }
}
