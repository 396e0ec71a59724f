//! The method's losses, each with its backward: the photometric loss of a frame (the mean of its
//! sub-exposure renders against the observation; one render with `blur_model = none`), the image
//! terms it is made of (L1, SSIM, the optional image-gradient L1), the event-generation loss, the
//! flow loss, the perceptual (LPIPS) loss, the as-isometric-as-possible regulariser of the human
//! Gaussians and the priors on their size and opacity (`sharpness`). The trainer weights and sums
//! them (`trainer::terms`).

pub mod aiap;
pub mod event;
pub mod image;
pub mod image_gradient;
pub mod optical_flow;
pub mod perceptual;
pub mod photometric;
pub mod sharpness;

/// The derivative of `slope·|d|` in `d`: `slope` where `d > 0`, `−slope` where `d < 0`, and 0 at
/// `d = 0` (and for NaN), the subgradient every L1 term of the method takes.
pub(crate) fn l1_slope<T>(d: T, slope: T) -> T
where
    T: Copy + PartialOrd + num_traits::Zero + std::ops::Neg<Output = T>,
{
    if d > T::zero() {
        slope
    } else if d < T::zero() {
        -slope
    } else {
        T::zero()
    }
}
