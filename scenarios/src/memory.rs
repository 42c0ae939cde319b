//! The process's memory. Resident memory is read from `/proc/self/status` (Linux), and the bytes
//! the program holds from glibc's `mallinfo2`. The runner samples both at every observation and
//! keeps them in `timing.json`, beside the wall times, because like them they vary from run to
//! run (the allocator, the thread count). The deterministic counterpart is the clouds each map
//! holds (`report.json`). Two allocator calls keep resident memory as flat as what is held:
//! [`keep_large_blocks_out_of_the_heap`] at start, and [`release_free_pages`] at every observation
//! (in `sgm ros`, every [`RELEASE_INTERVAL`] through [`release_free_pages_every`]).

use serde::Serialize;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

/// Resident memory at one time of the run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MemorySample {
    /// Simulated (or replayed) time, s.
    pub t: f64,
    /// Resident set size, MiB.
    pub resident_mb: f64,
    /// Bytes held by the program (allocated, not yet freed), MiB; `None` without glibc.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heap_mb: Option<f64>,
}

/// The resident set size now and its peak so far, MiB (`None` where `/proc` has no answer).
pub fn resident_mb() -> (Option<f64>, Option<f64>) {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else { return (None, None) };
    (status_kb(&status, "VmRSS:").map(mib), status_kb(&status, "VmHWM:").map(mib))
}

/// The resident memory at simulated time `t`, for `timing.json`.
pub fn sample(t: f64) -> Option<MemorySample> {
    resident_mb().0.map(|resident_mb| MemorySample { t, resident_mb, heap_mb: heap_mb() })
}

/// Bytes allocated and not yet freed, MiB: glibc's in-use bytes of every arena plus its mmapped
/// blocks. Resident memory minus this is what the allocator keeps for reuse.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn heap_mb() -> Option<f64> {
    // SAFETY: mallinfo2 takes no arguments and only reads the allocator's counters.
    let info = unsafe { libc::mallinfo2() };
    Some((info.uordblks + info.hblkhd) as f64 / (1024.0 * 1024.0))
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn heap_mb() -> Option<f64> {
    None
}

/// The mmap threshold this program sets, bytes: glibc's starting value.
pub const MMAP_THRESHOLD_BYTES: i32 = 128 * 1024;

/// Fixes glibc's mmap threshold at [`MMAP_THRESHOLD_BYTES`], unless `MALLOC_MMAP_THRESHOLD_` sets
/// it in the environment. Returns whether it was set here.
///
/// glibc serves a block of at least the threshold with a mapping of its own, which it returns to
/// the system when the block is freed. But each such free raises the threshold to the block's
/// size, up to 32 MiB. After the first full scans (216 KB), solver temporaries and loop-closure
/// submaps (MBs) have come and gone, blocks of those sizes come from the heap. Freed, they leave
/// holes that long-lived small blocks settle in, and the heap cannot shrink. Over the first 35
/// minutes of the endurance run, resident memory climbed by 12 MiB every 100 s while the clouds
/// held stayed at their budget (book: "Endurance"). With the threshold fixed, large blocks keep
/// their own mappings and leave nothing behind when freed.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn keep_large_blocks_out_of_the_heap() -> bool {
    if std::env::var_os("MALLOC_MMAP_THRESHOLD_").is_some() {
        return false;
    }
    // SAFETY: mallopt only changes a parameter of the allocator; any value is accepted or
    // refused (returning 0), never undefined.
    unsafe { libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1 }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn keep_large_blocks_out_of_the_heap() -> bool {
    false
}

/// Returns the allocator's free pages to the system (glibc's `malloc_trim(0)`), wherever they
/// lie in its heaps; returns whether any were. The runner calls it at every observation.
///
/// Freed blocks leave holes that glibc keeps resident: in 1200 s of the endurance scenario, while
/// what the program held stayed flat, the gap between resident memory and what is held grew from
/// 19 to 56 MiB, with the mmap threshold fixed
/// ([`keep_large_blocks_out_of_the_heap`]). A trim costs a walk over the free lists.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn release_free_pages() -> bool {
    // SAFETY: malloc_trim only returns free memory; blocks in use are untouched.
    unsafe { libc::malloc_trim(0) == 1 }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn release_free_pages() -> bool {
    false
}

/// Calls [`release_free_pages`] every `interval` on a thread of its own, until the returned guard
/// is dropped. For a program without observations to hang the call on: `sgm ros` runs for hours
/// on wall time, and gives the pages back every [`RELEASE_INTERVAL`].
pub fn release_free_pages_every(interval: Duration) -> std::io::Result<PeriodicRelease> {
    let (stop, stopped) = mpsc::channel::<()>();
    let thread = std::thread::Builder::new().name("sgm-release-pages".into()).spawn(move || {
        // Dropping the guard disconnects the channel and ends the wait at once.
        while let Err(RecvTimeoutError::Timeout) = stopped.recv_timeout(interval) {
            release_free_pages();
        }
    })?;
    Ok(PeriodicRelease { stop: Some(stop), thread: Some(thread) })
}

/// How often `sgm ros` gives free pages back: the runner's default observation interval
/// (`scenario.report_interval_s`), in wall time.
pub const RELEASE_INTERVAL: Duration = Duration::from_secs(10);

/// The thread of [`release_free_pages_every`]; dropping it stops the thread and waits for it.
pub struct PeriodicRelease {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for PeriodicRelease {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(thread) = self.thread.take() {
            // The thread only calls malloc_trim; a panic there has nothing to hand on.
            let _ = thread.join();
        }
    }
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
        let s = |t, resident_mb| MemorySample { t, resident_mb, heap_mb: None };
        let samples = [s(0.0, 50.0), s(10.0, 100.0), s(20.0, 95.0), s(30.0, 108.0)];
        let (lo, hi) = drift_after(&samples, 10.0).unwrap();
        assert!((lo + 0.05).abs() < 1e-12 && (hi - 0.08).abs() < 1e-12);
        assert_eq!(drift_after(&samples, 40.0), None);
    }
}
