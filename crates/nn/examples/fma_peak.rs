//! Sustained single-thread f32 fused multiply-add rate of this machine, 512- and 256-bit: the
//! ceiling that `docs/notes/benchmarks-history.md` (deformation, "Third pass") holds the GEMM kernels and the deformation target against.
//! Sixteen independent accumulator chains per width, so the rate is throughput- not latency-bound.
//!
//! `cargo run --release -p nn --example fma_peak`

#![allow(unsafe_code)]

use std::time::Instant;

#[cfg(target_arch = "x86_64")]
mod kernels {
    use std::arch::x86_64::*;

    /// `iters` × 16 FMAs on 16 × 16 lanes; returns a sum so the work is not optimised away.
    ///
    /// # Safety
    /// The CPU must support avx512f.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn zmm(iters: usize) -> f32 {
        let mut acc = [_mm512_set1_ps(0.0); 16];
        let (a, b) = (_mm512_set1_ps(0.999_999), _mm512_set1_ps(1e-7));
        for _ in 0..iters {
            for x in acc.iter_mut() {
                *x = _mm512_fmadd_ps(*x, a, b);
            }
        }
        acc.iter().map(|&x| _mm512_reduce_add_ps(x)).sum()
    }

    /// `iters` × 16 FMAs on 16 × 8 lanes.
    ///
    /// # Safety
    /// The CPU must support avx2 and fma.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn ymm(iters: usize) -> f32 {
        let mut acc = [_mm256_set1_ps(0.0); 16];
        let (a, b) = (_mm256_set1_ps(0.999_999), _mm256_set1_ps(1e-7));
        for _ in 0..iters {
            for x in acc.iter_mut() {
                *x = _mm256_fmadd_ps(*x, a, b);
            }
        }
        let mut lanes = [0f32; 8];
        let mut sum = 0.0;
        for x in acc {
            _mm256_storeu_ps(lanes.as_mut_ptr(), x);
            sum += lanes.iter().sum::<f32>();
        }
        sum
    }
}

fn main() {
    #[cfg(target_arch = "x86_64")]
    {
        let iters = 50_000_000;
        for _ in 0..3 {
            if std::arch::is_x86_feature_detected!("avx512f") {
                let t = Instant::now();
                // SAFETY: avx512f detected just above.
                let s = unsafe { kernels::zmm(iters) };
                let gflops = (iters * 16 * 16 * 2) as f64 / t.elapsed().as_secs_f64() / 1e9;
                println!("512-bit FMA: {gflops:.1} GFLOP/s (checksum {s})");
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                let t = Instant::now();
                // SAFETY: avx2 and fma detected just above.
                let s = unsafe { kernels::ymm(iters) };
                let gflops = (iters * 16 * 8 * 2) as f64 / t.elapsed().as_secs_f64() / 1e9;
                println!("256-bit FMA: {gflops:.1} GFLOP/s (checksum {s})");
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    println!("x86-64 only");
}
