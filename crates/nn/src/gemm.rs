//! Safe wrapper around `matrixmultiply`'s `sgemm`/`dgemm` (with `gemm_packing_free`, the only places in
//! the crate that need `unsafe`): every strided view is bounds-checked against its slice before the
//! raw call.
//!
//! On AVX-512 machines, f32 products with `alpha = 1`, `beta ∈ {0, 1}` and a row-major C go to the
//! packing-free kernel of `gemm_packing_free`, which gives the same bits as `matrixmultiply` (see there).
//!
//! `matrixmultiply` splits work over output blocks only (never over the inner dimension), so a GEMM
//! result does not depend on how many threads run it.

use crate::Real;

/// Largest index touched by an `rows × cols` view with strides `(rs, cs)`; `None` for negative strides.
fn max_index(rows: usize, cols: usize, rs: isize, cs: isize) -> Option<usize> {
    if rs < 0 || cs < 0 {
        return None;
    }
    Some((rows - 1) * rs as usize + (cols - 1) * cs as usize)
}

/// Panics unless the three views fit in their slices and C's view does not alias itself.
#[allow(clippy::too_many_arguments)]
fn check_views(
    m: usize,
    k: usize,
    n: usize,
    a_len: usize,
    rsa: isize,
    csa: isize,
    b_len: usize,
    rsb: isize,
    csb: isize,
    c_len: usize,
    rsc: isize,
    csc: isize,
) {
    let ok = |len: usize, r: usize, c: usize, rs: isize, cs: isize| matches!(max_index(r, c, rs, cs), Some(i) if i < len);
    assert!(ok(a_len, m, k, rsa, csa), "gemm: A view out of bounds");
    assert!(ok(b_len, k, n, rsb, csb), "gemm: B view out of bounds");
    assert!(ok(c_len, m, n, rsc, csc), "gemm: C view out of bounds");
    // C must not alias itself: one of the strides must step over the whole extent of the other.
    let (rsc, csc) = (rsc as usize, csc as usize);
    let distinct = m == 1 && (n == 1 || csc > 0)
        || n == 1 && rsc > 0
        || (csc > 0 && rsc >= csc * n)
        || (rsc > 0 && csc >= rsc * m);
    assert!(distinct, "gemm: C view aliases itself");
}

macro_rules! impl_real {
    // `$fast`: an optional faster path tried first (it returns whether it ran the product).
    ($t:ty, $f:ident $(, $fast:path)?) => {
        impl Real for $t {
            #[inline]
            fn of(x: f64) -> Self {
                x as $t
            }
            #[inline]
            fn as_f64(self) -> f64 {
                self as f64
            }
            #[allow(unsafe_code)]
            fn gemm_unchecked(
                m: usize,
                k: usize,
                n: usize,
                alpha: Self,
                a: &[Self],
                rsa: isize,
                csa: isize,
                b: &[Self],
                rsb: isize,
                csb: isize,
                beta: Self,
                c: &mut [Self],
                rsc: isize,
                csc: isize,
            ) {
                if m == 0 || n == 0 {
                    return;
                }
                if k == 0 {
                    // C = beta·C; matrixmultiply also handles this, but keep the k = 0 edge explicit.
                    for i in 0..m {
                        for j in 0..n {
                            let idx = i * rsc as usize + j * csc as usize;
                            c[idx] = if beta == 0.0 { 0.0 } else { beta * c[idx] };
                        }
                    }
                    return;
                }
                check_views(
                    m,
                    k,
                    n,
                    a.len(),
                    rsa,
                    csa,
                    b.len(),
                    rsb,
                    csb,
                    c.len(),
                    rsc,
                    csc,
                );
                $(
                    if $fast(m, k, n, alpha, a, rsa, csa, b, rsb, csb, beta, c, rsc, csc) {
                        return;
                    }
                )?
                // SAFETY: check_views proved every index the kernel touches lies inside its slice
                // (non-negative strides, max index < len) and that C's view does not alias itself;
                // A and B are shared borrows and C an exclusive one, so they cannot overlap.
                unsafe {
                    matrixmultiply::$f(
                        m,
                        k,
                        n,
                        alpha,
                        a.as_ptr(),
                        rsa,
                        csa,
                        b.as_ptr(),
                        rsb,
                        csb,
                        beta,
                        c.as_mut_ptr(),
                        rsc,
                        csc,
                    )
                }
            }
        }
    };
}

impl_real!(f32, sgemm, crate::gemm_packing_free::try_sgemm);
impl_real!(f64, dgemm);

/// General matrix product `C = alpha·op(A)·op(B) + beta·C` on dense row-major matrices.
///
/// `A` is `m × k` (stored `k × m` when `trans_a`), `B` is `k × n` (stored `n × k` when `trans_b`),
/// `C` is `m × n`. With `beta = 0` the previous contents of `C` are ignored (may be NaN).
///
/// # Panics
/// If a slice is shorter than its matrix.
pub fn gemm<T: Real>(
    m: usize,
    k: usize,
    n: usize,
    alpha: T,
    a: &[T],
    trans_a: bool,
    b: &[T],
    trans_b: bool,
    beta: T,
    c: &mut [T],
) {
    let (rsa, csa) = if trans_a {
        (1, m as isize)
    } else {
        (k as isize, 1)
    };
    let (rsb, csb) = if trans_b {
        (1, k as isize)
    } else {
        (n as isize, 1)
    };
    T::gemm_unchecked(
        m, k, n, alpha, a, rsa, csa, b, rsb, csb, beta, c, n as isize, 1,
    );
}
