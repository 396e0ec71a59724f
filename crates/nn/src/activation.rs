//! Element-wise activations (ReLU, LeakyReLU, sigmoid, softplus) and their backward passes.
//!
//! Backward functions take whichever forward quantity makes the derivative exact and cheap (the
//! input for ReLU/LeakyReLU/softplus, the output for sigmoid) and overwrite `dx`. At the ReLU kink
//! (`x = 0`) the derivative is taken as 0, as in PyTorch.

use crate::Real;
use rayon::prelude::*;

/// Elements per parallel chunk (fixed, so results never depend on the thread count).
const CHUNK: usize = 1 << 14;

fn map_inplace<T: Real>(x: &[T], y: &mut [T], f: impl Fn(T) -> T + Sync) {
    assert_eq!(
        x.len(),
        y.len(),
        "activation: input and output lengths differ"
    );
    y.par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .for_each(|(yc, xc)| {
            for (o, &i) in yc.iter_mut().zip(xc) {
                *o = f(i);
            }
        });
}

fn map2<T: Real>(a: &[T], g: &[T], d: &mut [T], f: impl Fn(T, T) -> T + Sync) {
    assert_eq!(a.len(), g.len(), "activation backward: lengths differ");
    assert_eq!(a.len(), d.len(), "activation backward: lengths differ");
    d.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(g.par_chunks(CHUNK)))
        .for_each(|(dc, (ac, gc))| {
            for ((o, &a), &g) in dc.iter_mut().zip(ac).zip(gc) {
                *o = f(a, g);
            }
        });
}

/// `y = max(x, 0)`. Panics if lengths differ.
pub fn relu_forward<T: Real>(x: &[T], y: &mut [T]) {
    map_inplace(x, y, |v| if v > T::zero() { v } else { T::zero() });
}

/// `dx = dy · [x > 0]` (input `x` of the forward pass).
pub fn relu_backward<T: Real>(x: &[T], dy: &[T], dx: &mut [T]) {
    map2(x, dy, dx, |x, g| if x > T::zero() { g } else { T::zero() });
}

/// `y = x` for `x > 0`, `slope·x` otherwise.
pub fn leaky_relu_forward<T: Real>(x: &[T], y: &mut [T], slope: T) {
    map_inplace(x, y, |v| if v > T::zero() { v } else { slope * v });
}

/// `dx = dy` for `x > 0`, `slope·dy` otherwise (input `x` of the forward pass).
pub fn leaky_relu_backward<T: Real>(x: &[T], dy: &[T], dx: &mut [T], slope: T) {
    map2(x, dy, dx, |x, g| if x > T::zero() { g } else { slope * g });
}

/// Logistic sigmoid `y = 1 / (1 + e^{−x})`, evaluated without overflow for large `|x|`.
pub fn sigmoid_forward<T: Real>(x: &[T], y: &mut [T]) {
    map_inplace(x, y, sigmoid);
}

/// `dx = dy · y · (1 − y)` (output `y` of the forward pass).
pub fn sigmoid_backward<T: Real>(y: &[T], dy: &[T], dx: &mut [T]) {
    map2(y, dy, dx, |y, g| g * y * (T::one() - y));
}

/// `y = ln(1 + e^x)`, evaluated as `max(x, 0) + ln(1 + e^{−|x|})` (no overflow).
pub fn softplus_forward<T: Real>(x: &[T], y: &mut [T]) {
    map_inplace(x, y, |v| v.max(T::zero()) + (-v.abs()).exp().ln_1p());
}

/// `dx = dy · sigmoid(x)` (input `x` of the forward pass).
pub fn softplus_backward<T: Real>(x: &[T], dy: &[T], dx: &mut [T]) {
    map2(x, dy, dx, |x, g| g * sigmoid(x));
}

#[inline]
fn sigmoid<T: Real>(v: T) -> T {
    if v >= T::zero() {
        T::one() / (T::one() + (-v).exp())
    } else {
        let e = v.exp();
        e / (T::one() + e)
    }
}
