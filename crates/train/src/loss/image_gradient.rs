//! The image-gradient term: the L1 distance between the finite differences of a prediction and of
//! its target, i.e. the total variation of the residual `R = pred − target`,
//!
//! `G = (Σ_{c,y,x<W−1} |R[c,y,x+1] − R[c,y,x]| + Σ_{c,y<H−1,x} |R[c,y+1,x] − R[c,y,x]|) / n`,
//!
//! `n` the number of differences, `C·(H·(W−1) + (H−1)·W)`. A residual that is constant over a
//! region costs nothing; one that changes from pixel to pixel — a missing edge, a texture drawn
//! too soft — costs its every step. An exposure's blur averages the fine structure of the sharp
//! image along the motion, so the photometric term's residual in that structure is small; this term
//! weighs it by its differences instead of its values. Images are planar (C, H, W).

use num_traits::Float;

/// `G` of `pred` against `target` (both planar with `channels` planes of `height × width`), and
/// with `grad` its gradient w.r.t. `pred` added into `grad` (same layout). 0 for an image with no
/// difference (a 1 × 1 plane). At a difference that is exactly zero the subgradient 0 is taken.
pub fn image_gradient_l1<T: Float>(
    pred: &[T],
    target: &[T],
    (channels, height, width): (usize, usize, usize),
    mut grad: Option<&mut [T]>,
) -> T {
    let hw = height * width;
    let count = channels * (height * width.saturating_sub(1) + height.saturating_sub(1) * width);
    if count == 0 {
        return T::zero();
    }
    let per = T::one() / T::from(count).unwrap_or_else(T::one);
    let residual = |i: usize| pred[i] - target[i];
    let mut sum = T::zero();
    let mut step = |i: usize, j: usize| {
        let d = residual(j) - residual(i);
        sum = sum + d.abs();
        if let Some(g) = grad.as_deref_mut() {
            let s = super::l1_slope(d, per);
            g[j] = g[j] + s;
            g[i] = g[i] - s;
        }
    };
    for c in 0..channels {
        for y in 0..height {
            for x in 0..width {
                let i = c * hw + y * width + x;
                if x + 1 < width {
                    step(i, i + 1);
                }
                if y + 1 < height {
                    step(i, i + width);
                }
            }
        }
    }
    sum * per
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual constant over the image costs nothing; a step in it costs its height once per
    /// difference that crosses it.
    #[test]
    fn a_constant_residual_is_free_and_a_step_costs_its_height() {
        let target = vec![0.3f64; 2 * 3 * 4];
        let offset: Vec<f64> = target.iter().map(|v| v + 0.1).collect();
        assert_eq!(image_gradient_l1(&offset, &target, (2, 3, 4), None), 0.0);
        // Plane 0 gains 0.2 on its right half (x ≥ 2): 3 rows cross it once.
        let mut step = target.clone();
        for y in 0..3 {
            for x in 2..4 {
                step[y * 4 + x] += 0.2;
            }
        }
        let n = 2.0 * (3.0 * 3.0 + 2.0 * 4.0);
        let g = image_gradient_l1(&step, &target, (2, 3, 4), None);
        assert!((g - 3.0 * 0.2 / n).abs() < 1e-15, "{g}");
    }

    /// The gradient of a single bright pixel pushes it down and its neighbours up.
    #[test]
    fn the_gradient_of_a_spike_lowers_it_and_raises_its_neighbours() {
        let target = vec![0.0f64; 9];
        let mut pred = target.clone();
        pred[4] = 1.0;
        let mut grad = vec![0.0; 9];
        image_gradient_l1(&pred, &target, (1, 3, 3), Some(&mut grad));
        assert!(grad[4] > 0.0);
        for i in [1, 3, 5, 7] {
            assert!(grad[i] < 0.0, "{i}: {grad:?}");
        }
        for i in [0, 2, 6, 8] {
            assert_eq!(grad[i], 0.0);
        }
    }
}
