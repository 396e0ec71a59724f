//! Four-lane vectors for the tile kernels: one lane per pixel column of a group of four.
//!
//! The portable backward kernel in [`crate::raster`] is written once against [`Lanes`] and runs on
//! - [`F32x4`] (x86-64, f32): SSE2 registers, baseline on every x86-64 CPU, so no runtime dispatch;
//! - [`Arr4`] (f64 for the gradient checks, and f32 on other architectures): four scalars, element
//!   by element.
//!
//! Every [`F32x4`] operation is the IEEE operation of its scalar counterpart lane by lane (add, sub,
//! mul, div and comparisons are exactly rounded in both; `exp` repeats [`crate::fast_exp_f32`]'s
//! operations), so a kernel gives the same bits on either implementation. The unit tests below
//! check that lane by lane on random and special values. (On CPUs with AVX-512 the f32 kernels
//! run 16 lanes a row instead, with the same bits: `raster/avx512.rs`.)

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

use crate::Real;

/// Four values of the working precision `T` with the handful of operations the tile kernels use.
pub trait Lanes<T: Real>:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Send
    + Sync
{
    /// Per-lane predicate (the result of a comparison).
    type Mask: Copy
        + BitAnd<Output = Self::Mask>
        + BitOr<Output = Self::Mask>
        + Not<Output = Self::Mask>;
    /// All four lanes `v`.
    fn splat(v: T) -> Self;
    /// Lanes `s[0..4]` (panics if `s` is shorter than 4).
    fn load(s: &[T]) -> Self;
    /// Writes the lanes to `s[0..4]` (panics if `s` is shorter than 4).
    fn store(self, s: &mut [T]);
    /// `self < o` per lane (false if either is NaN).
    fn lt(self, o: Self) -> Self::Mask;
    /// `self <= o` per lane.
    fn le(self, o: Self) -> Self::Mask;
    /// `self > o` per lane.
    fn gt(self, o: Self) -> Self::Mask;
    /// `self >= o` per lane.
    fn ge(self, o: Self) -> Self::Mask;
    /// `self != o` per lane (true if either is NaN).
    fn ne(self, o: Self) -> Self::Mask;
    /// `if m { a } else { b }` per lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// [`Real::splat_exp`] per lane.
    fn exp(self) -> Self;
    /// Number of lanes where `m` holds.
    fn count(m: Self::Mask) -> u32;
    /// The lanes as an array, lane 0 first.
    fn to_array(self) -> [T; 4];
}

/// Four scalars, operated on element by element (the portable implementation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arr4<T>(pub [T; 4]);

macro_rules! arr4_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<T: Real> $tr for Arr4<T> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                Arr4([
                    self.0[0] $op o.0[0],
                    self.0[1] $op o.0[1],
                    self.0[2] $op o.0[2],
                    self.0[3] $op o.0[3],
                ])
            }
        }
    };
}
arr4_op!(Add, add, +);
arr4_op!(Sub, sub, -);
arr4_op!(Mul, mul, *);
arr4_op!(Div, div, /);

/// Per-lane booleans of [`Arr4`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mask4(pub [bool; 4]);

impl BitAnd for Mask4 {
    type Output = Self;
    #[inline(always)]
    fn bitand(self, o: Self) -> Self {
        Mask4(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
}
impl BitOr for Mask4 {
    type Output = Self;
    #[inline(always)]
    fn bitor(self, o: Self) -> Self {
        Mask4(std::array::from_fn(|i| self.0[i] | o.0[i]))
    }
}
impl Not for Mask4 {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Mask4(self.0.map(|b| !b))
    }
}

impl<T: Real> Lanes<T> for Arr4<T> {
    type Mask = Mask4;
    #[inline(always)]
    fn splat(v: T) -> Self {
        Arr4([v; 4])
    }
    #[inline(always)]
    fn load(s: &[T]) -> Self {
        Arr4([s[0], s[1], s[2], s[3]])
    }
    #[inline(always)]
    fn store(self, s: &mut [T]) {
        s[..4].copy_from_slice(&self.0);
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Mask4 {
        Mask4(std::array::from_fn(|i| self.0[i] < o.0[i]))
    }
    #[inline(always)]
    fn le(self, o: Self) -> Mask4 {
        Mask4(std::array::from_fn(|i| self.0[i] <= o.0[i]))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> Mask4 {
        Mask4(std::array::from_fn(|i| self.0[i] > o.0[i]))
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Mask4 {
        Mask4(std::array::from_fn(|i| self.0[i] >= o.0[i]))
    }
    #[inline(always)]
    fn ne(self, o: Self) -> Mask4 {
        Mask4(std::array::from_fn(|i| self.0[i] != o.0[i]))
    }
    #[inline(always)]
    fn select(m: Mask4, a: Self, b: Self) -> Self {
        Arr4(std::array::from_fn(
            |i| if m.0[i] { a.0[i] } else { b.0[i] },
        ))
    }
    #[inline(always)]
    fn exp(self) -> Self {
        Arr4(self.0.map(T::splat_exp))
    }
    #[inline(always)]
    fn count(m: Mask4) -> u32 {
        m.0.iter().map(|&b| u32::from(b)).sum()
    }
    #[inline(always)]
    fn to_array(self) -> [T; 4] {
        self.0
    }
}

#[cfg(target_arch = "x86_64")]
pub use sse::{F32x4, M32x4};

#[cfg(target_arch = "x86_64")]
mod sse {
    //! SSE2 implementation for f32. SSE2 is part of the x86-64 baseline, so these intrinsics are
    //! safe to call; only the unaligned load and store take raw pointers, each after a length check.
    #![allow(unsafe_code)]

    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

    use super::Lanes;

    /// Evaluates an expression of SSE / SSE2 intrinsics.
    macro_rules! sse {
        ($e:expr) => {
            // SAFETY: the intrinsics' only requirement is the SSE / SSE2 target features, which
            // every x86-64 target has (they are part of the architecture's baseline).
            unsafe { $e }
        };
    }

    /// Four f32 lanes in one SSE register.
    #[derive(Clone, Copy, Debug)]
    pub struct F32x4(__m128);

    /// Per-lane all-ones / all-zeros bit masks of [`F32x4`].
    #[derive(Clone, Copy, Debug)]
    pub struct M32x4(__m128);

    macro_rules! sse_op {
        ($tr:ident, $f:ident, $intr:ident) => {
            impl $tr for F32x4 {
                type Output = Self;
                #[inline(always)]
                fn $f(self, o: Self) -> Self {
                    F32x4(sse!($intr(self.0, o.0)))
                }
            }
        };
    }
    sse_op!(Add, add, _mm_add_ps);
    sse_op!(Sub, sub, _mm_sub_ps);
    sse_op!(Mul, mul, _mm_mul_ps);
    sse_op!(Div, div, _mm_div_ps);

    impl BitAnd for M32x4 {
        type Output = Self;
        #[inline(always)]
        fn bitand(self, o: Self) -> Self {
            M32x4(sse!(_mm_and_ps(self.0, o.0)))
        }
    }
    impl BitOr for M32x4 {
        type Output = Self;
        #[inline(always)]
        fn bitor(self, o: Self) -> Self {
            M32x4(sse!(_mm_or_ps(self.0, o.0)))
        }
    }
    impl Not for M32x4 {
        type Output = Self;
        #[inline(always)]
        fn not(self) -> Self {
            M32x4(sse!(_mm_xor_ps(
                self.0,
                _mm_castsi128_ps(_mm_set1_epi32(-1))
            )))
        }
    }

    impl Lanes<f32> for F32x4 {
        type Mask = M32x4;
        #[inline(always)]
        fn splat(v: f32) -> Self {
            F32x4(sse!(_mm_set1_ps(v)))
        }
        #[inline(always)]
        fn load(s: &[f32]) -> Self {
            let s = &s[..4];
            // SAFETY: `s` has exactly four initialised f32; `loadu` has no alignment requirement.
            F32x4(unsafe { _mm_loadu_ps(s.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, s: &mut [f32]) {
            let s = &mut s[..4];
            // SAFETY: `s` has room for exactly four f32; `storeu` has no alignment requirement.
            unsafe { _mm_storeu_ps(s.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn lt(self, o: Self) -> M32x4 {
            M32x4(sse!(_mm_cmplt_ps(self.0, o.0)))
        }
        #[inline(always)]
        fn le(self, o: Self) -> M32x4 {
            M32x4(sse!(_mm_cmple_ps(self.0, o.0)))
        }
        #[inline(always)]
        fn gt(self, o: Self) -> M32x4 {
            M32x4(sse!(_mm_cmpgt_ps(self.0, o.0)))
        }
        #[inline(always)]
        fn ge(self, o: Self) -> M32x4 {
            M32x4(sse!(_mm_cmpge_ps(self.0, o.0)))
        }
        #[inline(always)]
        fn ne(self, o: Self) -> M32x4 {
            M32x4(sse!(_mm_cmpneq_ps(self.0, o.0)))
        }
        #[inline(always)]
        fn select(m: M32x4, a: Self, b: Self) -> Self {
            F32x4(sse!(_mm_or_ps(
                _mm_and_ps(m.0, a.0),
                _mm_andnot_ps(m.0, b.0)
            )))
        }
        /// [`crate::fast_exp_f32`] lane by lane, operation for operation.
        #[inline(always)]
        fn exp(self) -> Self {
            const LOG2E: f32 = std::f32::consts::LOG2_E;
            const LN2_HI: f32 = 0.693_145_75;
            const LN2_LO: f32 = 1.428_606_8e-6;
            const ROUND: f32 = 12_582_912.0;
            const ROUND_BITS: i32 = 0x4B40_0000;
            let s = Self::splat;
            let x = Self::select(self.lt(s(-87.0)), s(-87.0), self);
            let x = Self::select(x.gt(s(0.0)), s(0.0), x);
            let kr = x * s(LOG2E) + s(ROUND);
            let k = kr - s(ROUND);
            let r = x - k * s(LN2_HI) - k * s(LN2_LO);
            let p = s(1.0)
                + r * (s(1.0)
                    + r * (s(0.5)
                        + r * (s(1.0 / 6.0)
                            + r * (s(1.0 / 24.0) + r * (s(1.0 / 120.0) + r * s(1.0 / 720.0))))));
            let bits = sse!(_mm_sub_epi32(
                _mm_castps_si128(kr.0),
                _mm_set1_epi32(ROUND_BITS - 127)
            ));
            let scale = sse!(_mm_castsi128_ps(_mm_slli_epi32::<23>(bits)));
            p * F32x4(scale)
        }
        #[inline(always)]
        fn count(m: M32x4) -> u32 {
            (sse!(_mm_movemask_ps(m.0)) as u32).count_ones()
        }
        #[inline(always)]
        fn to_array(self) -> [f32; 4] {
            let mut a = [0.0f32; 4];
            self.store(&mut a);
            a
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values that exercise every branch of the kernels' lane operations: signed zeros, the exp
    /// clamps, tiny and huge magnitudes, NaN and infinities.
    fn samples() -> Vec<f32> {
        let mut v = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            -87.0,
            -87.5,
            -200.0,
            0.99,
            1.0 / 255.0,
            1e-4,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE / 4.0,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut state = 0x1234_5678_9abc_def0u64;
        for _ in 0..4000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let u = (state >> 40) as f32 / (1u64 << 24) as f32;
            let e = ((state >> 8) & 31) as i32 - 16;
            v.push((2.0 * u - 1.0) * 2f32.powi(e));
            v.push(-40.0 * u);
        }
        v
    }

    fn same(a: [f32; 4], b: [f32; 4]) -> bool {
        a.iter()
            .zip(&b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn sse_lanes_equal_the_scalar_operations_bit_for_bit() {
        let v = samples();
        let n = v.len();
        for i in 0..n {
            let a: [f32; 4] = std::array::from_fn(|l| v[(i + l) % n]);
            let b: [f32; 4] = std::array::from_fn(|l| v[(i * 7 + 3 * l + 1) % n]);
            let (fa, fb) = (F32x4::load(&a), F32x4::load(&b));
            let (sa, sb) = (Arr4(a), Arr4(b));
            assert!(same((fa + fb).to_array(), (sa + sb).to_array()));
            assert!(same((fa - fb).to_array(), (sa - sb).to_array()));
            assert!(same((fa * fb).to_array(), (sa * sb).to_array()));
            assert!(same((fa / fb).to_array(), (sa / sb).to_array()));
            assert!(
                same(fa.exp().to_array(), sa.exp().to_array()),
                "exp of {a:?}"
            );
            type Cmp<L, M> = fn(L, L) -> M;
            type CmpPair = (Cmp<F32x4, M32x4>, Cmp<Arr4<f32>, Mask4>);
            let cmps: [CmpPair; 5] = [
                (F32x4::lt, Arr4::lt),
                (F32x4::le, Arr4::le),
                (F32x4::gt, Arr4::gt),
                (F32x4::ge, Arr4::ge),
                (<F32x4 as Lanes<f32>>::ne, <Arr4<f32> as Lanes<f32>>::ne),
            ];
            for (f, s) in cmps {
                let (mf, ms) = (f(fa, fb), s(sa, sb));
                assert_eq!(F32x4::count(mf), Arr4::<f32>::count(ms));
                let pick = F32x4::select(mf, fa, fb).to_array();
                assert!(same(pick, Arr4::select(ms, sa, sb).to_array()));
                let both = f(fa, F32x4::splat(0.0)) & !mf | mf;
                let both_s = s(sa, Arr4::splat(0.0)) & !ms | ms;
                assert!(same(
                    F32x4::select(both, fa, fb).to_array(),
                    Arr4::select(both_s, sa, sb).to_array()
                ));
            }
        }
    }

    #[test]
    fn portable_lanes_follow_the_scalar_definitions() {
        let a = Arr4([1.0f64, -2.0, 0.5, 3.0]);
        let b = Arr4([2.0f64, -2.0, 0.25, -1.0]);
        assert_eq!((a + b).0, [3.0, -4.0, 0.75, 2.0]);
        assert_eq!((a / b).0, [0.5, 1.0, 2.0, -3.0]);
        assert_eq!(Arr4::<f64>::count(a.lt(b)), 1);
        assert_eq!(Arr4::select(a.ge(b), a, b).0, [2.0, -2.0, 0.5, 3.0]);
        assert_eq!(Arr4([0.0f64, -1.0, -2.0, -3.0]).exp().0[2], (-2.0f64).exp());
    }
}
