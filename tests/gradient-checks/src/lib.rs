//! Shared machinery for the workspace's finite-difference gradient checks.
//!
//! Every backward pass in the workspace is compared, in f64, against central finite differences of its
//! forward pass. This module holds the one implementation of the difference quotient and of the
//! comparison, so that every check states its tolerance the same way and reports every mismatch at
//! once. It must never loosen a comparison on its own: tolerances are always passed in by the caller,
//! next to the justification for them.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The generator of every check's random inputs, seeded: ChaCha8, the same stream on every platform.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// `n` values drawn uniformly from [-1, 1) by `rng`.
pub fn symmetric(rng: &mut impl Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

/// `n` values uniform in [-1, 1) from a fresh generator seeded with `seed` (see [`rng`]).
pub fn symmetric_from_seed(seed: u64, n: usize) -> Vec<f64> {
    symmetric(&mut rng(seed), n)
}

/// Mixed absolute/relative tolerance: an entry passes when
/// `|numeric − analytic| ≤ abs + rel · max(|numeric|, |analytic|)`.
#[derive(Clone, Copy, Debug)]
pub struct Tolerance {
    /// Absolute part (same units as the gradient).
    pub abs: f64,
    /// Relative part (dimensionless).
    pub rel: f64,
}

impl Tolerance {
    /// A tolerance with the given absolute and relative parts.
    pub const fn new(abs: f64, rel: f64) -> Self {
        Self { abs, rel }
    }
}

/// Central finite differences `(f(x + h e_i) − f(x − h e_i)) / 2h` of a scalar function for every
/// coordinate of `x`. Truncation error is O(h²·f'''), rounding error O(ε·|f|/h); with f64 and
/// `h ≈ 1e-5` both are ~1e-10 relative for well-scaled smooth functions.
pub fn central_differences(mut f: impl FnMut(&[f64]) -> f64, x: &[f64], h: f64) -> Vec<f64> {
    let mut probe = x.to_vec();
    (0..x.len())
        .map(|i| {
            let original = probe[i];
            probe[i] = original + h;
            let plus = f(&probe);
            probe[i] = original - h;
            let minus = f(&probe);
            probe[i] = original;
            (plus - minus) / (2.0 * h)
        })
        .collect()
}

/// Summary of one numeric-versus-analytic comparison.
#[derive(Clone, Debug)]
pub struct GradientComparison {
    /// Human-readable name of the checked quantity (used in failure messages).
    pub name: String,
    /// One line per entry outside the tolerance.
    pub mismatches: Vec<String>,
    /// ‖analytic − numeric‖₂ / max(‖numeric‖₂, tiny).
    pub relative_l2_error: f64,
    /// Cosine similarity between the two gradient vectors (1 when both are zero).
    pub cosine_similarity: f64,
    /// Largest absolute analytic entry.
    pub max_abs_analytic: f64,
    /// Largest absolute numeric entry.
    pub max_abs_numeric: f64,
}

impl GradientComparison {
    /// True when no entry is outside the tolerance.
    pub fn passed(&self) -> bool {
        self.mismatches.is_empty()
    }

    /// A multi-line report of the comparison.
    pub fn report(&self) -> String {
        let mut s = format!(
            "{}: {} mismatches, rel L2 {:.3e}, cosine {:.9}, max|ana| {:.3e}, max|num| {:.3e}",
            self.name,
            self.mismatches.len(),
            self.relative_l2_error,
            self.cosine_similarity,
            self.max_abs_analytic,
            self.max_abs_numeric
        );
        for m in self.mismatches.iter().take(40) {
            s.push_str("\n  ");
            s.push_str(m);
        }
        if self.mismatches.len() > 40 {
            s.push_str(&format!("\n  ... and {} more", self.mismatches.len() - 40));
        }
        s
    }
}

/// Compares an analytic gradient with a numeric one entry by entry under `tol`, and also checks the
/// zero/non-zero pattern: an entry that is exactly zero on one side while the other side is above
/// `tol.abs` is always a mismatch (a wrongly-zero gradient must not hide inside a loose tolerance).
pub fn compare(
    name: &str,
    numeric: &[f64],
    analytic: &[f64],
    tol: Tolerance,
) -> GradientComparison {
    assert_eq!(
        numeric.len(),
        analytic.len(),
        "{name}: numeric and analytic gradients differ in length"
    );
    let mut mismatches = Vec::new();
    let (mut diff2, mut num2, mut ana2, mut dot) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut max_ana, mut max_num) = (0.0f64, 0.0f64);
    for (i, (&n, &a)) in numeric.iter().zip(analytic).enumerate() {
        let err = (n - a).abs();
        let bound = tol.abs + tol.rel * n.abs().max(a.abs());
        let zero_pattern_broken =
            (a == 0.0 && n.abs() > tol.abs) || (n == 0.0 && a.abs() > tol.abs);
        // Written so that a NaN on either side counts as a mismatch.
        let within = err <= bound;
        if !within || zero_pattern_broken || !a.is_finite() {
            mismatches.push(format!(
                "[{i}] numeric {n:+.9e} analytic {a:+.9e} |diff| {err:.3e} > {bound:.3e}"
            ));
        }
        diff2 += (n - a) * (n - a);
        num2 += n * n;
        ana2 += a * a;
        dot += n * a;
        max_ana = max_ana.max(a.abs());
        max_num = max_num.max(n.abs());
    }
    let cosine_similarity = if num2 == 0.0 && ana2 == 0.0 {
        1.0
    } else {
        dot / (num2.sqrt() * ana2.sqrt()).max(f64::MIN_POSITIVE)
    };
    GradientComparison {
        name: name.to_string(),
        mismatches,
        relative_l2_error: diff2.sqrt() / num2.sqrt().max(1e-300),
        cosine_similarity,
        max_abs_analytic: max_ana,
        max_abs_numeric: max_num,
    }
}

/// Collects comparisons from many cases and asserts once at the end, so one failing run shows every
/// mismatch. Also asserts that at least one analytic gradient entry across all cases was non-zero
/// (a check that passes on all-zero gradients proves nothing).
#[derive(Default, Debug)]
pub struct GradientChecker {
    failures: Vec<String>,
    cases: usize,
    nonzero_cases: usize,
}

impl GradientChecker {
    /// An empty checker.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one comparison (see [`compare`]).
    pub fn check(&mut self, name: &str, numeric: &[f64], analytic: &[f64], tol: Tolerance) {
        let c = compare(name, numeric, analytic, tol);
        self.cases += 1;
        if c.max_abs_analytic > 0.0 {
            self.nonzero_cases += 1;
        }
        if !c.passed() {
            self.failures.push(c.report());
        }
    }

    /// Number of comparisons whose analytic gradient had a non-zero entry.
    pub fn nonzero_cases(&self) -> usize {
        self.nonzero_cases
    }

    /// Panics with every collected failure, or if no case had a non-zero analytic gradient.
    pub fn finish(self) {
        assert!(
            self.failures.is_empty(),
            "{} of {} gradient comparisons failed:\n{}",
            self.failures.len(),
            self.cases,
            self.failures.join("\n")
        );
        assert!(
            self.cases == 0 || self.nonzero_cases > 0,
            "all {} gradient comparisons had all-zero analytic gradients",
            self.cases
        );
    }
}

/// Checks the gradient of a loss of two inputs stacked as `[first, second]` (e.g. two renders of a
/// pair of frames): `numeric[j]` is the finite difference at input `probes[j]`, `analytic` the full
/// analytic gradient, `first_len` the length of the first input. Besides the comparison itself it
/// asserts that the negated gradient and the gradient with the second input's share zeroed both
/// *fail*, so the check would catch a wrong sign or a missing path to the second input.
pub fn check_pair_gradient(
    name: &str,
    numeric: &[f64],
    probes: &[usize],
    analytic: &[f64],
    first_len: usize,
    tol: Tolerance,
) {
    let ana: Vec<f64> = probes.iter().map(|&i| analytic[i]).collect();
    let mut checker = GradientChecker::new();
    checker.check(name, numeric, &ana, tol);
    let negated: Vec<f64> = ana.iter().map(|a| -a).collect();
    assert!(
        !compare(name, numeric, &negated, tol).passed(),
        "{name}: the negated gradient passes"
    );
    let no_second: Vec<f64> = probes
        .iter()
        .map(|&i| if i >= first_len { 0.0 } else { analytic[i] })
        .collect();
    assert!(
        !compare(name, numeric, &no_second, tol).passed(),
        "{name}: a zero gradient for the second input passes"
    );
    checker.finish();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeded_values_are_reproducible_and_in_range() {
        let a = symmetric_from_seed(5, 1000);
        assert_eq!(a, symmetric_from_seed(5, 1000));
        assert_ne!(a, symmetric_from_seed(6, 1000));
        assert!(a.iter().all(|v| (-1.0..1.0).contains(v)));
        // Both halves of the interval are drawn (a generator stuck on one sign fails this).
        assert!(a.iter().any(|&v| v < -0.5) && a.iter().any(|&v| v > 0.5));
    }

    #[test]
    fn central_differences_of_a_cubic_are_accurate() {
        let x = [0.3, -1.2];
        let g = central_differences(|v| v[0].powi(3) + v[0] * v[1], &x, 1e-5);
        assert!((g[0] - (3.0 * 0.09 - 1.2)).abs() < 1e-9);
        assert!((g[1] - 0.3).abs() < 1e-9);
    }

    #[test]
    fn compare_flags_a_wrong_sign_and_a_missing_term() {
        let num = [1.0, 2.0, 0.5];
        let wrong_sign = [-1.0, 2.0, 0.5];
        assert!(!compare("sign", &num, &wrong_sign, Tolerance::new(1e-8, 1e-6)).passed());
        let zero = [1.0, 2.0, 0.0];
        assert!(!compare("zero", &num, &zero, Tolerance::new(1e-8, 0.5)).passed());
        assert!(compare("same", &num, &num, Tolerance::new(1e-8, 1e-6)).passed());
    }
}

/// The share of finite-difference probes a property test's validation must keep: 90 %, judged
/// over the whole run (every case so far) rather than per case, where one Gaussian sitting near a
/// hard step (a tile edge, the 1/255 cut) can discard 3 of its 13 probes and fail a 90 % rule on
/// its own. Judged from the case at which at least `min_probes` were counted (a test picks about
/// a sixth of its run's probes; each case is then judged on the run so far).
pub struct ProbeTally {
    min_probes: usize,
    probes: std::sync::atomic::AtomicUsize,
    valid: std::sync::atomic::AtomicUsize,
}

impl ProbeTally {
    /// An empty tally (for a `static` inside the property test) judged from `min_probes` on.
    pub const fn new(min_probes: usize) -> Self {
        Self {
            min_probes,
            probes: std::sync::atomic::AtomicUsize::new(0),
            valid: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    /// Adds one case's `probes` and `valid` probes; `Err` names the run's counts when, over at
    /// least `min_probes` probes, fewer than 90 % were valid.
    pub fn add(&self, probes: usize, valid: usize) -> Result<(), String> {
        self.add_counts(probes, valid).map_err(|(kept, all)| {
            format!("over the run so far only {kept} of {all} probes avoided a hard step")
        })
    }

    /// [`ProbeTally::add`] for any share a run must hold at 90 % (such as the cases in which a
    /// check caught an injected error): `Err((hits, all))`, the run's counts so far.
    pub fn add_counts(&self, all: usize, hits: usize) -> Result<(), (usize, usize)> {
        use std::sync::atomic::Ordering::Relaxed;
        let all = self.probes.fetch_add(all, Relaxed) + all;
        let hits = self.valid.fetch_add(hits, Relaxed) + hits;
        if all >= self.min_probes && hits * 10 < all * 9 {
            return Err((hits, all));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tally_tests {
    use super::ProbeTally;

    #[test]
    fn the_tally_judges_the_run_so_far_once_it_has_enough_probes() {
        let run = ProbeTally::new(40);
        assert!(run.add(26, 23).is_ok(), "not judged below 40 probes");
        assert!(run.add(26, 26).is_ok(), "49 of 52 valid over the run");
        assert!(run.add(30, 20).is_err(), "69 of 82 valid over the run");
        let poor = ProbeTally::new(40);
        assert!(poor.add(50, 44).is_err(), "44 of 50 valid");
    }
}
