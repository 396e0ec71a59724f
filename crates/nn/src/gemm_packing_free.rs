//! A packing-free f32 GEMM for AVX-512 (16 lanes) and for AVX2 with FMA (8 lanes, on CPUs
//! without AVX-512: AMD Zen 2/3, Intel client cores). `matrixmultiply` packs both operands of
//! every call, which on the project's narrow products (the deformation networks' `240 × 64 ·
//! 64 × 64` chunks, the flow network's convolutions with 2–64 output channels, the colour
//! networks) costs up to two thirds of its kernel time; this kernel reads `A` in place (one
//! broadcast per element and row block) and `B` in place when its rows are contiguous and a
//! multiple of 16 wide, else from a zero-padded copy. Large products are split over rows with
//! rayon.
//!
//! **Same bits as `matrixmultiply`.** `matrixmultiply` computes every output element as in-order
//! chains of fused multiply-adds over blocks of `KC = 256` values of `k`, each chain starting from
//! zero and applied as `c ← 1·ab + β·c` (β for the first block, 1 after); splitting over threads
//! only partitions the output. This kernel does exactly that for `α = 1` and `β ∈ {0, 1}` with a
//! row-major `C`; every other call returns `false` and goes to `matrixmultiply`. The unit tests
//! compare both bit for bit on random shapes.

#![allow(unsafe_code)]

use std::cell::RefCell;

use rayon::prelude::*;

/// `matrixmultiply`'s f32 `KC`: the length of one fused multiply-add chain over `k`.
const KC: usize = 256;
/// Products with `m·k + k·n` below this run on the calling thread (`matrixmultiply`'s own
/// threading threshold); larger ones are split over rows with rayon.
const PARALLEL_WORK: usize = 1 << 15;
/// Rows per rayon task of a large product (a multiple of every row-block height).
const TASK_ROWS: usize = 96;

thread_local! {
    /// Zero-padded copy of `B` for small products (per thread, reused).
    static PACKED_B: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Copies op(B) (`k × n`, strides `rsb`, `csb`) into `out` as `k × npad`, zero-padded.
fn pack_b(k: usize, n: usize, b: &[f32], rsb: usize, csb: usize, npad: usize, out: &mut Vec<f32>) {
    out.clear();
    out.resize(k * npad, 0.0);
    for (kk, row) in out.chunks_exact_mut(npad).enumerate() {
        pack_row(&mut row[..n], &b[kk * rsb..], csb);
    }
}

/// [`pack_b`] with the rows copied in parallel (for the large products).
fn pack_b_parallel(
    k: usize,
    n: usize,
    b: &[f32],
    rsb: usize,
    csb: usize,
    npad: usize,
    out: &mut Vec<f32>,
) {
    out.clear();
    out.resize(k * npad, 0.0);
    out.par_chunks_exact_mut(npad)
        .enumerate()
        .for_each(|(kk, row)| pack_row(&mut row[..n], &b[kk * rsb..], csb));
}

/// One row of op(B): `row[j] = b[j · csb]`.
fn pack_row(row: &mut [f32], b: &[f32], csb: usize) {
    if csb == 1 {
        row.copy_from_slice(&b[..row.len()]);
    } else {
        for (j, v) in row.iter_mut().enumerate() {
            *v = b[j * csb];
        }
    }
}

/// The vector width this CPU runs the kernel at: 16 lanes with AVX-512F, 8 with AVX2 and FMA, or
/// `None` (every product goes to `matrixmultiply`) without either or when the environment variable
/// `E_SEM3DGS_PORTABLE_KERNELS` is set (same bits: for measuring one against the other on a CPU,
/// as the rasterizer's kernels are).
#[cfg(target_arch = "x86_64")]
fn lanes() -> Option<usize> {
    static LANES: std::sync::OnceLock<Option<usize>> = std::sync::OnceLock::new();
    *LANES.get_or_init(|| {
        if std::env::var_os("E_SEM3DGS_PORTABLE_KERNELS").is_some() {
            None
        } else {
            detected_lanes()
        }
    })
}

/// The widest kernel this CPU has (16, 8 or none), whatever the environment says.
#[cfg(target_arch = "x86_64")]
fn detected_lanes() -> Option<usize> {
    if std::arch::is_x86_feature_detected!("avx512f") {
        Some(16)
    } else if std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        Some(8)
    } else {
        None
    }
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
            && k > 0
            && csc == 1
            && rsc >= n as isize
            && rsa >= 0
            && csa >= 0
            && rsb >= 0
            && csb >= 0;
        let Some(lanes) = lanes().filter(|_| applies) else {
            return false;
        };
        let (rsa, csa, rsb, csb, rsc) = (
            rsa as usize,
            csa as usize,
            rsb as usize,
            csb as usize,
            rsc as usize,
        );
        let beta_one = beta == 1.0;
        let in_place = csb == 1 && n.is_multiple_of(16);
        let npad = n.div_ceil(16) * 16;
        if m * k + k * n < PARALLEL_WORK {
            if in_place {
                run(lanes, m, k, n, a, rsa, csa, b, rsb, c, rsc, beta_one);
            } else {
                PACKED_B.with(|cell| {
                    let mut packed = cell.borrow_mut();
                    pack_b(k, n, b, rsb, csb, npad, &mut packed);
                    run(lanes, m, k, n, a, rsa, csa, &packed, npad, c, rsc, beta_one);
                });
            }
        } else {
            let mut packed = Vec::new();
            let (bv, rsb) = if in_place {
                (b, rsb)
            } else {
                pack_b_parallel(k, n, b, rsb, csb, npad, &mut packed);
                (&packed[..], npad)
            };
            // A product of few rows (a weight gradient `dYᵀ·X`: m = a layer's width, k = the
            // batch) is still split in two, so that both threads share it. Each element's sum
            // does not depend on which rows a task holds: same bits.
            let task_rows = if m <= TASK_ROWS {
                m.div_ceil(2).max(1)
            } else {
                TASK_ROWS
            };
            c.par_chunks_mut(task_rows * rsc)
                .enumerate()
                .for_each(|(t, c_rows)| {
                    let i0 = t * task_rows;
                    if i0 < m {
                        let rows = task_rows.min(m - i0);
                        run(
                            lanes,
                            rows,
                            k,
                            n,
                            &a[i0 * rsa..],
                            rsa,
                            csa,
                            bv,
                            rsb,
                            c_rows,
                            rsc,
                            beta_one,
                        );
                    }
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

/// `C (m × n) = A·B (+ C)` on the calling thread, in `KC` blocks of `k` (β applies to the first
/// block, later blocks accumulate). `b` holds `k` rows of stride `rsb`, each readable for `n`
/// rounded up to 16 values.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
fn run(
    lanes: usize,
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    rsa: usize,
    csa: usize,
    b: &[f32],
    rsb: usize,
    c: &mut [f32],
    rsc: usize,
    beta_one: bool,
) {
    // Every index the kernel touches, checked once (the caller's views imply these; a bad stride
    // must panic here rather than read out of bounds).
    let npad = n.div_ceil(16) * 16;
    assert!(
        (m - 1) * rsa + (k - 1) * csa < a.len(),
        "gemm_packing_free: A out of bounds"
    );
    assert!(
        (k - 1) * rsb + npad <= b.len(),
        "gemm_packing_free: B out of bounds"
    );
    assert!(
        (m - 1) * rsc + n <= c.len(),
        "gemm_packing_free: C out of bounds"
    );
    let mut kb = 0;
    while kb < k {
        let kc = (k - kb).min(KC);
        let gemm = if lanes == 16 { imp::gemm } else { imp8::gemm };
        // SAFETY: the caller detected avx512f (16 lanes) or avx2 and fma (8 lanes); the asserts
        // above bound every read of A (rows < m, columns < k), of B (rows < k, 16- or 8-wide loads
        // within `npad` of each row start) and every write of C (rows < m, columns < n, masked or
        // copied through a buffer beyond).
        unsafe {
            gemm(
                m,
                kc,
                n,
                a.as_ptr().add(kb * csa),
                rsa,
                csa,
                b.as_ptr().add(kb * rsb),
                rsb,
                c.as_mut_ptr(),
                rsc,
                beta_one || kb > 0,
            )
        };
        kb += KC;
    }
}

/// `panel`, the row loop of a column panel over a module's `block`, compiled for the module's
/// target features (`"avx512f"` or `"avx2,fma"`): one definition for both widths.
#[cfg(target_arch = "x86_64")]
macro_rules! define_panel {
    ($feature:literal) => {
        /// All rows of one column panel: blocks of `MR` rows, then of 4, 2 and 1.
        ///
        /// # Safety
        /// As [`block`], for every row of the panel.
        #[target_feature(enable = $feature)]
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
            // Full blocks, then the remainder in blocks of 4, 2 and 1 rows (a lone row streams its B
            // rows for only NV multiply-adds per load).
            macro_rules! rows_of {
                ($r:expr) => {
                    while m - i >= $r {
                        block::<{ $r }, NV>(
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
                        i += $r;
                    }
                };
            }
            rows_of!(MR);
            rows_of!(4);
            rows_of!(2);
            rows_of!(1);
        }
    };
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

    define_panel!("avx512f");

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

/// The 8-lane twin of [`imp`] for CPUs with AVX2 and FMA: the same chains of fused multiply-adds in
/// increasing `k`, so the same bits. A panel's last partial vector of `C` goes through a small
/// buffer instead of a masked load and store (`vmaskmovps` is microcoded on AMD).
#[cfg(target_arch = "x86_64")]
mod imp8 {
    use std::arch::x86_64::*;

    /// One block of `MR` rows × `8·NV` columns (the first `w` of which are stored), as
    /// [`super::imp`]'s `block`.
    ///
    /// # Safety
    /// avx2 and fma available; `a + r·rsa + kk·csa` readable for r < MR, kk < k; `b + kk·rsb + j`
    /// readable for kk < k, j < 8·NV; `c + r·rsc + j` writable for r < MR, j < w ≤ 8·NV.
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
        let mut acc = [[_mm256_setzero_ps(); NV]; MR];
        for kk in 0..k {
            let brow = b.add(kk * rsb);
            let mut bv = [_mm256_setzero_ps(); NV];
            for (v, x) in bv.iter_mut().enumerate() {
                *x = _mm256_loadu_ps(brow.add(8 * v));
            }
            let acol = a.add(kk * csa);
            for (r, row) in acc.iter_mut().enumerate() {
                let av = _mm256_set1_ps(*acol.add(r * rsa));
                for (x, &bx) in row.iter_mut().zip(&bv) {
                    *x = _mm256_fmadd_ps(av, bx, *x);
                }
            }
        }
        for (r, row) in acc.iter().enumerate() {
            let crow = c.add(r * rsc);
            for (v, &x) in row.iter().enumerate() {
                let cols = (w - 8 * v).min(8); // ≥ 1 by the caller's choice of NV
                let p = crow.add(8 * v);
                if cols == 8 {
                    let out = if beta_one {
                        _mm256_add_ps(x, _mm256_loadu_ps(p))
                    } else {
                        x
                    };
                    _mm256_storeu_ps(p, out);
                } else {
                    let mut tail = [0.0f32; 8];
                    if beta_one {
                        std::ptr::copy_nonoverlapping(p, tail.as_mut_ptr(), cols);
                    }
                    let out = if beta_one {
                        _mm256_add_ps(x, _mm256_loadu_ps(tail.as_ptr()))
                    } else {
                        x
                    };
                    _mm256_storeu_ps(tail.as_mut_ptr(), out);
                    std::ptr::copy_nonoverlapping(tail.as_ptr(), p, cols);
                }
            }
        }
    }

    define_panel!("avx2,fma");

    /// `C (m × n) = A·B (+ C)`, in panels of up to 16 columns.
    ///
    /// # Safety
    /// avx2 and fma available; A readable at `r·rsa + kk·csa`, B at `kk·rsb + j` for j < n rounded
    /// up to 8, C writable at `r·rsc + j` for j < n.
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
            let w = (n - j).min(16);
            let (bj, cj) = (b.add(j), c.add(j));
            // Register budget (16 ymm): MR·NV accumulators + NV B vectors + one broadcast.
            match w.div_ceil(8) {
                2 => panel::<6, 2>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
                _ => panel::<12, 1>(m, k, a, rsa, csa, bj, rsb, cj, rsc, w, beta_one),
            }
            j += 16;
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
        if detected_lanes().is_none() {
            eprintln!("neither avx512f nor avx2 with fma here: the fast path is never taken");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for case in 0..400 {
            // Shapes of the chunked MLPs and everything around them, edges included; every 10th
            // case large (several KC blocks of k, split over rayon tasks), and every 10th a weight
            // gradient's (few rows, a long k).
            let (k, m, n) = if case % 10 == 4 {
                (
                    rng.gen_range(1000..=6000),
                    rng.gen_range(1..=96),
                    rng.gen_range(1..=80),
                )
            } else if case % 10 == 9 {
                (
                    rng.gen_range(200..=900),
                    rng.gen_range(100..=700),
                    rng.gen_range(1..=150),
                )
            } else {
                (
                    if case % 5 == 0 {
                        256
                    } else {
                        rng.gen_range(1..=256)
                    },
                    rng.gen_range(1..=300),
                    if case % 7 == 0 {
                        64
                    } else {
                        rng.gen_range(1..=130)
                    },
                )
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
            assert!(fast, "case {case}: {m}×{k}×{n} declined");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&got),
                bits(&want),
                "case {case}: {m}×{k}×{n} ta {ta} tb {tb} beta {beta} pad {pad}"
            );
        }
    }

    #[test]
    fn declines_what_it_cannot_match() {
        let (a, b) = (vec![1.0f32; 12], vec![1.0f32; 12]);
        let mut c = vec![0.0f32; 16];
        // α ≠ 1, β ∉ {0, 1}, column-major C.
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
