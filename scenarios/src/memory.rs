//! The process's resident memory, read from `/proc/self/status` (Linux): sampled by the runner
//! at every observation and kept in `timing.json`, beside the wall times, because like them it
//! varies from run to run (the allocator, the thread count). The deterministic counterpart is
//! the clouds each map holds (`report.json`).

use serde::Serialize;

/// Resident memory at one time of the run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MemorySample {
    /// Simulated (or replayed) time, s.
    pub t: f64,
    /// Resident set size, MiB.
    pub resident_mb: f64,
}

/// The resident set size now and its peak so far, MiB (`None` where `/proc` has no answer).
pub fn resident_mb() -> (Option<f64>, Option<f64>) {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else { return (None, None) };
    (status_kb(&status, "VmRSS:").map(mib), status_kb(&status, "VmHWM:").map(mib))
}

/// The resident memory at simulated time `t`, for `timing.json`.
pub fn sample(t: f64) -> Option<MemorySample> {
    resident_mb().0.map(|resident_mb| MemorySample { t, resident_mb })
}

fn mib(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

/// The value of a `Name:   123 kB` line of `/proc/<pid>/status`.
fn status_kb(status: &str, name: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with(name))?;
    let value = line[name.len()..].trim().strip_suffix("kB")?.trim();
    value.parse().ok()
}

/// The change of the samples after `from_t` relative to the first of them, as (lowest, highest)
/// fractions: (−0.02, 0.05) means they stayed within −2 % and +5 % of where they started.
pub fn drift_after(samples: &[MemorySample], from_t: f64) -> Option<(f64, f64)> {
    let mut later = samples.iter().filter(|s| s.t >= from_t);
    let first = later.next()?.resident_mb;
    if first <= 0.0 {
        return None;
    }
    let (lo, hi) = later.fold((first, first), |(lo, hi), s| (lo.min(s.resident_mb), hi.max(s.resident_mb)));
    Some((lo / first - 1.0, hi / first - 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_status_lines() {
        let status = "Name:\tsgm\nVmHWM:\t  204800 kB\nVmRSS:\t  102400 kB\nThreads:\t3\n";
        assert_eq!(status_kb(status, "VmRSS:"), Some(102_400));
        assert_eq!(status_kb(status, "VmHWM:"), Some(204_800));
        assert_eq!(status_kb(status, "VmSwap:"), None);
        assert_eq!(status_kb("VmRSS:\tlots kB\n", "VmRSS:"), None);
        // This process has a /proc on Linux, and its peak is at least its present.
        if let (Some(now), Some(peak)) = resident_mb() {
            assert!(now > 0.0 && peak >= now);
        }
    }

    #[test]
    fn drift_is_relative_to_the_first_sample_of_the_span() {
        let s = |t, resident_mb| MemorySample { t, resident_mb };
        let samples = [s(0.0, 50.0), s(10.0, 100.0), s(20.0, 95.0), s(30.0, 108.0)];
        let (lo, hi) = drift_after(&samples, 10.0).unwrap();
        assert!((lo + 0.05).abs() < 1e-12 && (hi - 0.08).abs() < 1e-12);
        assert_eq!(drift_after(&samples, 40.0), None);
    }
}
