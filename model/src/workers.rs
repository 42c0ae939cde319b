//! Threads a function may spread its work over, with answers that do not depend on how many.
//!
//! The science stays synchronous: a call that is handed [`Workers`] returns when its work is
//! done, and it splits only work whose pieces are independent (each piece's answer a function
//! of its input alone), then folds the pieces' answers in their input order, exactly as one
//! thread would. So its result is bit for bit the same with any number of threads; only the
//! wall time changes. ICP's correspondence passes are the one such split today
//! (`perception::icp::register_to`).

use std::ops::Range;
use std::sync::Arc;

/// A pool of threads to split independent work over, or none (the caller's thread does it all).
#[derive(Clone, Default)]
pub struct Workers(Option<Arc<rayon::ThreadPool>>);

impl Workers {
    /// No pool: all work on the caller's thread.
    pub fn sequential() -> Self {
        Self(None)
    }

    /// Work split over `pool` (shared with whatever else runs on it).
    pub fn on(pool: Arc<rayon::ThreadPool>) -> Self {
        Self(Some(pool))
    }

    /// How many threads the work may use.
    pub fn threads(&self) -> usize {
        self.0.as_ref().map_or(1, |pool| pool.current_num_threads())
    }

    /// `piece` over consecutive ranges of `0..len`, each about `len / (4 · threads)` long but at
    /// least `min_len`, in the ranges' order. With one thread, or fewer than `2 · min_len`
    /// items, `None`: the caller does the work itself, without splitting.
    pub fn split<R: Send>(
        &self,
        len: usize,
        min_len: usize,
        piece: impl Fn(Range<usize>) -> R + Sync + Send,
    ) -> Option<Vec<R>> {
        use rayon::prelude::*;
        let pool = self.0.as_ref().filter(|pool| pool.current_num_threads() > 1)?;
        let min_len = min_len.max(1);
        if len < 2 * min_len {
            return None;
        }
        let size = len.div_ceil(4 * pool.current_num_threads()).max(min_len);
        let starts: Vec<usize> = (0..len).step_by(size).collect();
        Some(pool.install(|| starts.into_par_iter().map(|start| piece(start..(start + size).min(len))).collect()))
    }
}

impl std::fmt::Debug for Workers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Workers({} threads)", self.threads())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_cover_the_range_in_order() {
        let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap());
        let workers = Workers::on(pool);
        for len in [0, 1, 19, 20, 21, 100, 1001] {
            let pieces = workers.split(len, 10, |r| r);
            match pieces {
                None => assert!(len < 20, "{len}"),
                Some(pieces) => {
                    let flat: Vec<usize> = pieces.into_iter().flatten().collect();
                    assert_eq!(flat, (0..len).collect::<Vec<_>>());
                }
            }
        }
        assert!(Workers::sequential().split(1000, 1, |r| r).is_none());
        assert_eq!(Workers::sequential().threads(), 1);
        assert_eq!(workers.threads(), 3);
    }
}
