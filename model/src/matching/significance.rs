//! A-contrario significance of a rigid hypothesis (beyond the paper; in the spirit of ORSA,
//! Moisan & Stival 2004): how many hypotheses this good would chance produce?
//!
//! Null model: the remote objects land uniformly in the local graph's horizontal bounding box,
//! expanded by the inlier radius (area A). A remote object of label l then falls within radius r
//! of a local object it may match with probability p_m(r) = min(1, c(l) · π r² / A), c(l) the
//! number of such local objects. A hypothesis is fitted to 2 matches; with n remote objects inside
//! the box and the inliers' horizontal residuals sorted, r_(1) ≤ … ≤ r_(k), the radius is chosen
//! adaptively as in ORSA: for each j ≥ 3,
//!
//!   NFA_j = N_tests · (n − 2) · P[Bin(n − 2, p̄(r_(j))) ≥ j − 2],
//!
//! the factor n − 2 paying for the choice of j, N_tests the number of hypotheses scored, and
//! NFA = min_j NFA_j. NFA ≤ ε (`max_false_alarms`) means fewer than ε such coincidences are
//! expected over the whole search: the transform is accepted as significant.

/// ln P[Bin(n, p) ≥ k].
pub fn ln_binomial_tail(n: usize, k: usize, p: f64) -> f64 {
    ln_binomial_tail_with(&LnTable::new(n), n, k, p)
}

/// ln v and ln v! for v ≤ a bound, summed in the order a direct sum would take (same bits).
pub struct LnTable {
    ln: Vec<f64>,
    ln_fact: Vec<f64>,
}

impl LnTable {
    pub fn new(max: usize) -> Self {
        let ln: Vec<f64> = (0..=max.max(1)).map(|v| (v as f64).ln()).collect();
        let mut ln_fact = vec![0.0; ln.len()];
        for v in 2..ln.len() {
            ln_fact[v] = ln_fact[v - 1] + ln[v];
        }
        Self { ln, ln_fact }
    }
}

/// ln P[Bin(n, p) ≥ k] with logarithms from `table` (built for at least n).
fn ln_binomial_tail_with(table: &LnTable, n: usize, k: usize, p: f64) -> f64 {
    if k == 0 {
        return 0.0;
    }
    if k > n || p <= 0.0 {
        return f64::NEG_INFINITY;
    }
    if p >= 1.0 {
        return 0.0;
    }
    let (lp, lq) = (p.ln(), (1.0 - p).ln());
    let ln_n = table.ln_fact[n];
    let mut ln_k_fact = table.ln_fact[k];
    let mut ln_nk_fact = table.ln_fact[n - k];
    let mut max = f64::NEG_INFINITY;
    let mut terms = Vec::with_capacity(n - k + 1);
    for j in k..=n {
        if j > k {
            ln_k_fact += table.ln[j];
            ln_nk_fact -= table.ln[n - j + 1];
        }
        let term = ln_n - ln_k_fact - ln_nk_fact + j as f64 * lp + (n - j) as f64 * lq;
        max = max.max(term);
        terms.push(term);
    }
    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
}

/// log10 NFA of `inliers` out of `trials` objects each matching by chance with probability `p`,
/// over `tests` hypotheses.
pub fn log10_nfa(tests: usize, trials: usize, inliers: usize, p: f64) -> f64 {
    log10_nfa_with(&LnTable::new(trials), tests, trials, inliers, p)
}

fn log10_nfa_with(table: &LnTable, tests: usize, trials: usize, inliers: usize, p: f64) -> f64 {
    let tail = if inliers <= 2 { 0.0 } else { ln_binomial_tail_with(table, trials.saturating_sub(2), inliers - 2, p) };
    (tests.max(1) as f64).log10() + tail / std::f64::consts::LN_10
}

/// Adaptive-radius log10 NFA: `residuals` are the inliers' horizontal residuals (any order),
/// `p_at` gives the chance probability at a radius. Minimum over j of NFA_j (see module doc).
pub fn log10_nfa_adaptive(tests: usize, trials: usize, residuals: &mut [f64], p_at: impl Fn(f64) -> f64) -> f64 {
    residuals.sort_by(f64::total_cmp);
    let choices = (trials.saturating_sub(2).max(1) as f64).log10();
    let mut best = (tests.max(1) as f64).log10();
    let table = LnTable::new(trials);
    for j in 3..=residuals.len() {
        best = best.min(log10_nfa_with(&table, tests, trials, j, p_at(residuals[j - 1])) + choices);
    }
    best
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
            assert!(
                (got - want).abs() < 1e-12 * want.max(1e-300).max(1.0) && (got / want - 1.0).abs() < 1e-9,
                "{n} {k} {p}: {got} vs {want}"
            );
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

    #[test]
    fn adaptive_radius_rewards_tight_inliers() {
        let p = |r: f64| 0.01 * r * r;
        let mut tight = [0.1, 0.2, 0.1, 0.3, 0.2];
        let mut loose = [2.0, 2.1, 1.9, 2.4, 2.2];
        let a = log10_nfa_adaptive(50, 20, &mut tight, p);
        let b = log10_nfa_adaptive(50, 20, &mut loose, p);
        assert!(a < b - 3.0, "{a} {b}");
        // Never better than the fixed-radius test at the largest residual, minus the choice factor.
        let fixed = log10_nfa(50, 20, 5, p(2.4)) + (18f64).log10();
        assert!((b - fixed).abs() < 1e-9 || b < fixed);
        // Too few inliers: no evidence, NFA = number of tests.
        assert_eq!(log10_nfa_adaptive(50, 20, &mut [0.1, 0.2], p), 50f64.log10());
    }
}
