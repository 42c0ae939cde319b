//! How many robots' work runs at once (`sgm run --threads N`, `sgm replay --threads N`). Every
//! robot has a thread of its own (the team's); this bounds how many of them run at the
//! same time, and how many robots' sensors are simulated at once. The report does not depend
//! on it: only the wall time does.

use sgm_model::workers::Workers;
use std::num::NonZeroUsize;
use std::sync::Arc;

/// A number of threads, at least one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Threads(NonZeroUsize);

#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum ThreadsError {
    #[error("--threads 0: a run needs at least one thread (leave --threads out to use all {0} cores)")]
    Zero(usize),
}

impl Threads {
    /// One thread per core of this machine (what the OS lets this process use).
    pub fn all_cores() -> Self {
        Self(cores())
    }

    /// One thread: robots take turns.
    pub fn one() -> Self {
        Self(NonZeroUsize::MIN)
    }

    /// Exactly `n` threads, however many cores there are (tests and benches).
    pub fn exactly(n: NonZeroUsize) -> Self {
        Self(n)
    }

    /// What a user asked for: 0 is an error; more than the machine's cores is cut to them, with
    /// a warning (more would only take turns on the same cores).
    pub fn requested(n: usize) -> Result<Self, ThreadsError> {
        let cores = cores();
        let n = NonZeroUsize::new(n).ok_or(ThreadsError::Zero(cores.get()))?;
        if n > cores {
            tracing::warn!(
                requested = n.get(),
                cores = cores.get(),
                "--threads {n} is more than this machine's {cores} cores: using {cores}"
            );
            return Ok(Self(cores));
        }
        Ok(Self(n))
    }

    pub fn get(self) -> usize {
        self.0.get()
    }

    /// A rayon pool of this many threads for work split over robots; `None` for one thread (the
    /// work runs on the caller's).
    pub fn pool(self) -> Result<Option<rayon::ThreadPool>, rayon::ThreadPoolBuildError> {
        match self.get() {
            1 => Ok(None),
            n => rayon::ThreadPoolBuilder::new().num_threads(n).build().map(Some),
        }
    }

    /// A rayon pool of this many threads that run only on cores nothing else wants (Linux's
    /// idle scheduling class, [`run_in_background`]): for work that can wait, such as the
    /// sensors of the next step.
    pub fn background_pool(self) -> Result<rayon::ThreadPool, rayon::ThreadPoolBuildError> {
        rayon::ThreadPoolBuilder::new()
            .num_threads(self.get())
            .thread_name(|k| format!("sgm-background-{k}"))
            .start_handler(|_| {
                run_in_background();
            })
            .build()
    }

    /// [`Threads::pool`] as the [`Workers`] one robot's registrations split their work over,
    /// so a core that ran out of robots at a barrier helps the robot still running.
    pub fn workers(self) -> Result<Workers, String> {
        let pool = self.pool().map_err(|e| format!("{self} threads: {e}"))?.map(Arc::new);
        Ok(pool.map_or_else(Workers::sequential, Workers::on))
    }
}

impl Default for Threads {
    fn default() -> Self {
        Self::all_cores()
    }
}

impl std::fmt::Display for Threads {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

/// Moves the calling thread into Linux's idle scheduling class (`SCHED_IDLE`): it runs only
/// when a core would otherwise idle. Returns whether it was moved; elsewhere (glibc's Linux
/// only, as for the allocator calls of `memory.rs`), or if refused, the thread keeps its
/// priority: the work is the same, only the robots may be slowed by it, and a refusal is
/// logged once as a warning.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn run_in_background() -> bool {
    static REFUSED: std::sync::Once = std::sync::Once::new();
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pid 0 is the calling thread; SCHED_IDLE takes priority 0, and lowering one's own
    // policy needs no privilege. Nothing but this thread's scheduling changes.
    let moved = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } == 0;
    if !moved {
        let why = std::io::Error::last_os_error();
        REFUSED.call_once(|| {
            tracing::warn!("background threads stay at normal priority ({why}): the robots share their cores with them")
        });
    }
    moved
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn run_in_background() -> bool {
    false
}

fn cores() -> NonZeroUsize {
    std::thread::available_parallelism().unwrap_or(NonZeroUsize::MIN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_is_refused_and_too_many_is_cut_to_the_cores() {
        let cores = cores().get();
        assert_eq!(Threads::requested(0), Err(ThreadsError::Zero(cores)));
        assert!(ThreadsError::Zero(cores).to_string().contains("--threads 0"));
        assert_eq!(Threads::requested(cores + 5).map(Threads::get), Ok(cores));
        assert_eq!(Threads::requested(1).map(Threads::get), Ok(1));
        assert_eq!(Threads::all_cores().get(), cores);
    }
}
