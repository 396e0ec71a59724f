//! A packing-free f32 GEMM for AVX-512 on the small, narrow products of chunked MLPs (the
//! deformation networks run every layer as `rows × 64 · 64 × 64`-like products on chunks of a few
//! hundred rows). `matrixmultiply` packs both operands of every call, which on such shapes costs
//! about two thirds of its kernel time; this kernel reads `A` in place (one broadcast per element
//! and row block) and `B` in place when its rows are contiguous and a multiple of 16 wide, else from
//! a zero-padded copy.
//!
//! **Same bits as `matrixmultiply`.** Only calls where `matrixmultiply` would compute every output
//! element as one in-order chain of fused multiply-adds over `k` starting from zero — `k` at most
//! its `KC` block of 256 and single-threaded (`m·k + k·n < 2¹⁵`) — followed by `c ← 1·ab + β·c`
//! with `α = 1` and `β ∈ {0, 1}` are taken; every other call returns `false` and goes to
//! `matrixmultiply`. The unit tests compare both bit for bit on random shapes.

#![allow(unsafe_code)]

use std::cell::RefCell;

/// Largest `k` served: `matrixmultiply`'s f32 `KC`, below which it does not split the sum over `k`.
const MAX_K: usize = 256;
/// `matrixmultiply` runs a product on several threads from `m·k + k·n ≥ 2¹⁵` on (its `threading`
/// feature); larger products stay with it.
const MAX_WORK: usize = 1 << 15;

thread_local! {
    /// Zero-padded copy of `B` when it cannot be read in place (per thread, reused).
    static PACKED_B: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Runs `C = op(A)·op(B) + β·C` (`α = 1`) on the AVX-512 path if it applies, returning whether it
/// did. Strides are in elements; the caller has checked that every view lies inside its slice.
#[allow(clippy::too_many_arguments)]
pub(crate) fn try_sgemm(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: &[f32],
    rsa: isize,
    csa: isize,
    b: &[f32],
    rsb: isize,
    csb: isize,
    beta: f32,
    c: &mut [f32],
    rsc: isize,
    csc: isize,
) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let applies = alpha == 1.0
            && (beta == 0.0 || beta == 1.0)
            && m > 0
            && n > 0
            && (1..=MAX_K).contains(&k)
            && m * k + k * n < MAX_WORK
            && csc == 1
            && rsc >= n as isize
            && rsa >= 0
            && csa >= 0
            && rsb >= 0
            && csb >= 0
            && std::arch::is_x86_feature_detected!("avx512f");
        if !applies {
            return false;
        }
        let (rsa, csa, rsc) = (rsa as usize, csa as usize, rsc as usize);
        let beta_one = beta == 1.0;
        if csb == 1 && n.is_multiple_of(16) && rsb as usize >= n {
            // SAFETY: avx512f was detected above; the caller proved that A's and C's views lie
            // inside `a` and `c` and B's inside `b` (row stride `rsb`, `n` contiguous columns,
            // which the 16-wide loads cover exactly since 16 divides n).
            unsafe {
                imp::gemm(
                    m,
                    k,
                    n,
                    a.as_ptr(),
                    rsa,
                    csa,
                    b.as_ptr(),
                    rsb as usize,
                    c.as_mut_ptr(),
                    rsc,
                    beta_one,
                )
            };
        } else {
            let npad = n.div_ceil(16) * 16;
            PACKED_B.with(|cell| {
                let mut packed = cell.borrow_mut();
                packed.clear();
                packed.resize(k * npad, 0.0);
                let (rsb, csb) = (rsb as usize, csb as usize);
                for (kk, row) in packed.chunks_exact_mut(npad).enumerate() {
                    let row = &mut row[..n];
                    if csb == 1 {
                        row.copy_from_slice(&b[kk * rsb..kk * rsb + n]);
                    } else {
                        for (j, v) in row.iter_mut().enumerate() {
                            *v = b[kk * rsb + j * csb];
                        }
                    }
                }
                // SAFETY: as above for A and C; B is the packed `k × npad` copy, whose rows the
                // 16-wide loads cover exactly.
                unsafe {
                    imp::gemm(
                        m,
                        k,
                        n,
                        a.as_ptr(),
                        rsa,
                        csa,
                        packed.as_ptr(),
                        npad,
                        c.as_mut_ptr(),
                        rsc,
                        beta_one,
                    )
                };
            });
        }
        true
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (m, k, n, alpha, a, rsa, csa, b, rsb, csb, beta, c, rsc, csc);
        false
    }
}

#[cfg(target_arch = "x86_64")]
mod imp {
    use std::arch::x86_64::*;

    /// One block of `MR` rows × `16·NV` columns (the first `w` of which are stored):
    /// `acc = Σ_k a[r, k]·b[k, :]` as one fused multiply-add chain per element in increasing `k`,
    /// then `c = acc` or `c = acc + c`.
    ///
    /// # Safety
    /// avx512f available; `a + r·rsa + kk·csa` readable for r < MR, kk < k; `b + kk·rsb + j`
    /// readable for kk < k, j < 16·NV; `c + r·rsc + j` writable for r < MR, j < w ≤ 16·NV.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn block<const MR: usize, const NV: usize>(
        k: usize,
        a: *const f32,
        rsa: usize,
        csa: usize,
        b: *const f32,
        rsb: usize,
        c: *mut f32,
        rsc: usize,
        w: usize,
        beta_one: bool,
    ) {
        let mut acc = [[_mm512_setzero_ps(); NV]; MR];
        for kk in 0..k {
            let brow = b.add(kk * rsb);
            let mut bv = [_mm512_setzero_ps(); NV];
            for (v, x) in bv.iter_mut().enumerate() {
                *x = _mm512_loadu_ps(brow.add(16 * v));
            }
            let acol = a.add(kk * csa);
            for (r, row) in acc.iter_mut().enumerate() {
                let av = _mm512_set1_ps(*acol.add(r * rsa));
                for (x, &bx) in row.iter_mut().zip(&bv) {
                    *x = _mm512_fmadd_ps(av, bx, *x);
                }
            }
        }
        for (r, row) in acc.iter().enumerate() {
            let crow = c.add(r * rsc);
            for (v, &x) in row.iter().enumerate() {
                let cols = w - 16 * v; // ≥ 1 by the caller's choice of NV
                let mask: __mmask16 = if cols >= 16 {
                    0xFFFF
                } else {
                    (1u16 << cols) - 1
                };
                let p = crow.add(16 * v);
                let out = if beta_one {
                    _mm512_add_ps(x, _mm512_maskz_loadu_ps(mask, p))
                } else {
                    x
                };
                _mm512_mask_storeu_ps(p, mask, out);
            }
        }
    }

    /// All rows of one column panel: blocks of `MR` rows, then single rows.
    ///
    /// # Safety
    /// As [`block`], for every row of the panel.
    #[target_feature(enable = "avx512f")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn panel<const MR: usize, const NV: usize>(
        m: usize,
        k: usize,
        a: *const f32,
        rsa: usize,
        csa: usize,
        b: *const f32,
        rsb: usize,
        c: *mut f32,
        rsc: usize,
        w: usize,
        beta_one: bool,
    ) {
        let mut i = 0;
        while i + MR <= m {
            block::<MR, NV>(
                k,
                a.add(i * rsa),
                rsa,
                csa,
                b,
                rsb,
                c.add(i * rsc),
                rsc,
                w,
                beta_one,
            );
            i += MR;
        }
        while i < m {
            block::<1, NV>(
                k,
                a.add(i * rsa),
                rsa,
                csa,
                b,
                rsb,
                c.add(i * rsc),
                rsc,
                w,
                beta_one,
            );
            i += 1;
        }
    }

    /// `C (m × n) = A·B (+ C)`, in panels of up to 64 columns.
    ///
    /// # Safety
    /// avx512f available; A readable at `r·rsa + kk·csa`, B at `kk·rsb + j` for j < n rounded up
    /// to 16, C writable at `r·rsc + j` for j < n.
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn gemm(
        m: usize,
        k: usize,
        n: usize,
        a: *const f32,
        rsa: usize,
        csa: usize,
        b: *const f32,
        rsb: usize,
        c: *mut f32,
        rsc: usize,
        beta_one: bool,
    ) {
        let mut j = 0;
        while j < n {
            let w = (n - j).min(64);
            let (bj, cj) = (b.add(j), c.add(j));
            // Register budget (32 zmm): MR·NV accumulators + NV B vectors + one broadcast.
            match w.div_ceil(16) {
                4 => panel::<6, 4>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
                3 => panel::<8, 3>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
                2 => panel::<12, 2>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
                _ => panel::<12, 1>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
            }
            j += 64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// `matrixmultiply` on the same views.
    #[allow(clippy::too_many_arguments)]
    fn reference(
        m: usize,
        k: usize,
        n: usize,
        a: &[f32],
        (rsa, csa): (isize, isize),
        b: &[f32],
        (rsb, csb): (isize, isize),
        beta: f32,
        c: &mut [f32],
        rsc: isize,
    ) {
        // SAFETY: the views are built by the test to fit their slices (checked by `try_sgemm`'s
        // callers in production; here by construction: see `case`).
        unsafe {
            matrixmultiply::sgemm(
                m,
                k,
                n,
                1.0,
                a.as_ptr(),
                rsa,
                csa,
                b.as_ptr(),
                rsb,
                csb,
                beta,
                c.as_mut_ptr(),
                rsc,
                1,
            )
        }
    }

    #[test]
    fn same_bits_as_matrixmultiply_on_random_shapes() {
        if !std::arch::is_x86_feature_detected!("avx512f") {
            eprintln!("no avx512f on this machine: the fast path is never taken");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut taken = 0;
        for case in 0..400 {
            // Shapes of the chunked MLPs and everything around them, edges included.
            let k = if case % 5 == 0 {
                256
            } else {
                rng.gen_range(1..=256)
            };
            let m = rng.gen_range(1..=300);
            let n = if case % 7 == 0 {
                64
            } else {
                rng.gen_range(1..=130)
            };
            let (ta, tb) = (rng.gen_bool(0.5), rng.gen_bool(0.5));
            let beta = if rng.gen_bool(0.5) { 0.0 } else { 1.0 };
            let pad = if rng.gen_bool(0.3) { 3 } else { 0 }; // C row stride > n
            let a: Vec<f32> = (0..m * k).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let b: Vec<f32> = (0..k * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let c0: Vec<f32> = (0..m * (n + pad))
                .map(|_| rng.gen_range(-1.0..1.0))
                .collect();
            let sa = if ta { (1, m as isize) } else { (k as isize, 1) };
            let sb = if tb { (1, k as isize) } else { (n as isize, 1) };
            let rsc = (n + pad) as isize;
            let mut want = c0.clone();
            reference(m, k, n, &a, sa, &b, sb, beta, &mut want, rsc);
            let mut got = c0.clone();
            let fast = try_sgemm(
                m, k, n, 1.0, &a, sa.0, sa.1, &b, sb.0, sb.1, beta, &mut got, rsc, 1,
            );
            assert_eq!(fast, m * k + k * n < MAX_WORK, "case {case}: {m}×{k}×{n}");
            if fast {
                taken += 1;
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&got),
                    bits(&want),
                    "case {case}: {m}×{k}×{n} ta {ta} tb {tb} beta {beta} pad {pad}"
                );
            }
        }
        assert!(taken > 100, "only {taken} cases took the fast path");
    }

    #[test]
    fn declines_what_it_cannot_match() {
        let (a, b) = (vec![1.0f32; 4 * 300], vec![1.0f32; 300 * 4]);
        let mut c = vec![0.0f32; 16];
        // k above matrixmultiply's KC block, α ≠ 1, β ∉ {0, 1}, column-major C.
        assert!(!try_sgemm(
            4, 300, 4, 1.0, &a, 300, 1, &b, 4, 1, 0.0, &mut c, 4, 1
        ));
        assert!(!try_sgemm(
            4, 3, 4, 2.0, &a, 3, 1, &b, 4, 1, 0.0, &mut c, 4, 1
        ));
        assert!(!try_sgemm(
            4, 3, 4, 1.0, &a, 3, 1, &b, 4, 1, 0.5, &mut c, 4, 1
        ));
        assert!(!try_sgemm(
            4, 3, 4, 1.0, &a, 3, 1, &b, 4, 1, 0.0, &mut c, 1, 4
        ));
    }
}
