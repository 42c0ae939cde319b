//! Every robot's actors live on a thread of their own (an actix `Arbiter`), and the team's
//! work at a step is a set of jobs, one per robot, run on those threads at most `threads` at a
//! time. A robot alone on its thread handles its inputs in the same order whatever the other
//! robots do meanwhile, and robots meet only through the radio, which the team flushes in a
//! fixed order between jobs ([`sgm_actors::transport::InProcessRadio::flush`]): so a run gives
//! the same report on 1, 2 or 16 threads.

use actix_rt::{Arbiter, ArbiterHandle};
use std::future::Future;
use tokio::sync::mpsc::{unbounded_channel, UnboundedSender};

/// One robot's thread. It lives as long as the team and is reused when the robot restarts.
pub(crate) struct RobotThread {
    arbiter: Option<Arbiter>,
}

impl RobotThread {
    /// Starts the thread. Must be called inside an actix system.
    pub(crate) fn start() -> Self {
        Self { arbiter: Some(Arbiter::new()) }
    }

    pub(crate) fn handle(&self) -> Option<ArbiterHandle> {
        self.arbiter.as_ref().map(Arbiter::handle)
    }
}

impl Drop for RobotThread {
    /// Stops the thread (its actors are dropped with it) and waits for it to end.
    fn drop(&mut self) {
        if let Some(arbiter) = self.arbiter.take() {
            arbiter.stop();
            if arbiter.join().is_err() {
                tracing::warn!("a robot's thread ended with a panic");
            }
        }
    }
}

/// Sends its job's result (or `None`, if the job was dropped unfinished: it panicked, or its
/// thread had stopped) when dropped, so that the caller always hears back.
struct Reply<R> {
    index: usize,
    result: Option<R>,
    to: UnboundedSender<(usize, Option<R>)>,
}

impl<R> Drop for Reply<R> {
    fn drop(&mut self) {
        let _ = self.to.send((self.index, self.result.take()));
    }
}

/// Runs each job on its thread, at most `threads` at once; returns their results in the jobs'
/// order (`None`: the job did not finish — it panicked or its thread had stopped).
pub(crate) async fn run_jobs<R, F, Fut>(jobs: Vec<(ArbiterHandle, F)>, threads: usize) -> Vec<Option<R>>
where
    R: Send + 'static,
    F: FnOnce() -> Fut + Send + 'static,
    Fut: Future<Output = R> + 'static,
{
    let total = jobs.len();
    let (to, mut replies) = unbounded_channel();
    let mut results: Vec<Option<R>> = std::iter::repeat_with(|| None).take(total).collect();
    let mut waiting = jobs.into_iter().enumerate();
    let (mut running, mut finished) = (0, 0);
    while finished < total {
        while running < threads.max(1) {
            let Some((index, (arbiter, job))) = waiting.next() else { break };
            let reply = Reply { index, result: None, to: to.clone() };
            // If the thread is gone the closure is dropped unrun, and its reply says so.
            arbiter.spawn_fn(move || {
                actix_rt::spawn(async move {
                    let mut reply = reply;
                    reply.result = Some(job().await);
                });
            });
            running += 1;
        }
        // Every job's reply is sent exactly once, when it is dropped; we hold a sender.
        let Some((index, result)) = replies.recv().await else { break };
        if let Some(slot) = results.get_mut(index) {
            *slot = result;
        }
        running -= 1;
        finished += 1;
    }
    results
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    #[actix_rt::test]
    async fn results_come_back_in_order_and_never_more_than_threads_run_at_once() {
        let threads: Vec<RobotThread> = (0..5).map(|_| RobotThread::start()).collect();
        let (now, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let jobs = threads
            .iter()
            .enumerate()
            .map(|(k, thread)| {
                let (now, peak) = (now.clone(), peak.clone());
                let job = move || async move {
                    let running = now.fetch_add(1, Ordering::SeqCst) + 1;
                    peak.fetch_max(running, Ordering::SeqCst);
                    std::thread::sleep(std::time::Duration::from_millis(20));
                    now.fetch_sub(1, Ordering::SeqCst);
                    k * 10
                };
                (thread.handle().unwrap(), job)
            })
            .collect();
        let results = run_jobs(jobs, 2).await;
        assert_eq!(results, vec![Some(0), Some(10), Some(20), Some(30), Some(40)]);
        let peak = peak.load(Ordering::SeqCst);
        assert!((1..=2).contains(&peak), "{peak} jobs ran at once");
    }

    #[actix_rt::test]
    async fn a_job_that_panics_or_whose_thread_stopped_answers_none() {
        let alive = RobotThread::start();
        let mut stopped = RobotThread::start();
        let handle = stopped.handle().unwrap();
        drop(stopped.arbiter.take().map(|a| {
            a.stop();
            a.join()
        }));
        let jobs = vec![
            (alive.handle().unwrap(), Box::new(|| 1_usize) as Box<dyn FnOnce() -> usize + Send>),
            (alive.handle().unwrap(), Box::new(|| -> usize { panic!("a bug in a job") })),
            (handle, Box::new(|| 3_usize)),
        ];
        let jobs = jobs.into_iter().map(|(h, f)| (h, move || async move { f() })).collect();
        assert_eq!(run_jobs(jobs, 3).await, vec![Some(1), None, None]);
    }
}
