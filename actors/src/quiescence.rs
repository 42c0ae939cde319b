//! When has a robot team finished reacting? Every handled message bumps a per-thread activity
//! count (`containment::contained` calls `record_activity`); [`until_quiet`] yields to the
//! runtime until a few consecutive yields pass with no handler running. The scenario runner
//! and bag replay call it between virtual-time steps, so every consequence of step k is handled
//! before step k + 1 — which is what makes runs deterministic. The count is per thread because an actix system runs
//! its actors on one thread: concurrent systems (parallel tests) do not see each other.

use std::cell::Cell;

thread_local! {
    static ACTIVITY: Cell<u64> = const { Cell::new(0) };
}

/// Records one handled message on this thread.
pub(crate) fn record_activity() {
    ACTIVITY.with(|a| a.set(a.get().wrapping_add(1)));
}

/// Messages handled on this thread so far.
pub fn activity() -> u64 {
    ACTIVITY.with(Cell::get)
}

/// Consecutive idle yields that count as quiet. A message sent with `do_send` wakes its actor,
/// which the runtime polls within one yield of the sender; two spare rounds cover the actor's
/// own wake-ups.
const QUIET_YIELDS: u32 = 4;

/// Yields until no handler has run for [`QUIET_YIELDS`] consecutive yields; returns how many
/// messages were handled meanwhile.
pub async fn until_quiet() -> u64 {
    let start = activity();
    let mut idle = 0;
    let mut last = start;
    while idle < QUIET_YIELDS {
        actix_rt::task::yield_now().await;
        let now = activity();
        if now == last {
            idle += 1;
        } else {
            idle = 0;
            last = now;
        }
    }
    last.wrapping_sub(start)
}
