//! A-contrario significance of a rigid hypothesis (beyond the paper; in the spirit of ORSA,
//! Moisan & Stival 2004): how many hypotheses this good would chance produce?
//!
//! Null model: the remote objects land uniformly in the local graph's horizontal bounding box,
//! expanded by the inlier radius r (area A). A remote object of label l then becomes an inlier
//! with probability p_m = min(1, c(l) · π r² / A), c(l) the number of local objects it may match.
//! A hypothesis is fitted to 2 matches, so with n remote objects inside the box and k inliers,
//!
//!   NFA = N_tests · P[Bin(n − 2, p̄) ≥ k − 2],
//!
//! N_tests the number of hypotheses scored. NFA ≤ ε (`max_false_alarms`) means fewer than ε such
//! coincidences are expected over the whole search: the transform is accepted as significant.

/// ln P[Bin(n, p) ≥ k].
pub fn ln_binomial_tail(n: usize, k: usize, p: f64) -> f64 {
    if k == 0 {
        return 0.0;
    }
    if k > n || p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return 0.0;
    }
    let ln_fact = |m: usize| (2..=m).map(|v| (v as f64).ln()).sum::<f64>();
    let (lp, lq) = (p.ln(), (1.0 - p).ln());
    let ln_n = ln_fact(n);
    let mut ln_k_fact = ln_fact(k);
    let mut ln_nk_fact = ln_fact(n - k);
    let mut terms = Vec::with_capacity(n - k + 1);
    for j in k..=n {
        if j > k {
            ln_k_fact += (j as f64).ln();
            ln_nk_fact -= ((n - j + 1) as f64).ln();
        }
        terms.push(ln_n - ln_k_fact - ln_nk_fact + j as f64 * lp + (n - j) as f64 * lq);
    }
    let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
}

/// log10 NFA of `inliers` out of `trials` objects each matching by chance with probability `p`,
/// over `tests` hypotheses.
pub fn log10_nfa(tests: usize, trials: usize, inliers: usize, p: f64) -> f64 {
    let tail = if inliers <= 2 { 0.0 } else { ln_binomial_tail(trials.saturating_sub(2), inliers - 2, p) };
    (tests.max(1) as f64).log10() + tail / std::f64::consts::LN_10
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exact_tail(n: usize, k: usize, p: f64) -> f64 {
        let binom = |n: usize, j: usize| (0..j).fold(1.0, |acc, t| acc * (n - t) as f64 / (t + 1) as f64);
        (k..=n).map(|j| binom(n, j) * p.powi(j as i32) * (1.0 - p).powi((n - j) as i32)).sum()
    }

    #[test]
    fn tail_matches_direct_sum() {
        for &(n, k, p) in &[(10, 3, 0.1), (30, 12, 0.18), (6, 2, 0.013), (50, 50, 0.5), (20, 1, 0.3)] {
            let got = ln_binomial_tail(n, k, p).exp();
            let want = exact_tail(n, k, p);
            assert!((got - want).abs() < 1e-12 * want.max(1e-300).max(1.0) && (got / want - 1.0).abs() < 1e-9, "{n} {k} {p}: {got} vs {want}");
        }
        assert_eq!(ln_binomial_tail(5, 0, 0.2), 0.0);
        assert_eq!(ln_binomial_tail(5, 6, 0.2), f64::NEG_INFINITY);
        assert_eq!(ln_binomial_tail(5, 2, 1.0), 0.0);
    }

    #[test]
    fn nfa_grows_with_tests_and_shrinks_with_inliers() {
        let a = log10_nfa(100, 30, 8, 0.05);
        assert!(log10_nfa(1000, 30, 8, 0.05) > a);
        assert!(log10_nfa(100, 30, 12, 0.05) < a);
        assert_eq!(log10_nfa(10, 30, 2, 0.05), 1.0);
    }
}
