//! Panic containment. A panic in a handler — a bug meeting data nobody foresaw — must not take
//! the process down, nor the other robots in it, nor this robot's map. [`contained`] runs a
//! handler body under `catch_unwind`; on a panic it logs what panicked, drops the message being
//! handled and stops the actor, and the actor's actix `Supervisor` restarts it with its state
//! (each actor's `restarting` hook repairs what a half-done handler may have left).

use actix::{Actor, ActorContext, Context};
use std::any::Any;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

thread_local! {
    static BUSY: RefCell<BTreeMap<&'static str, Duration>> = const { RefCell::new(BTreeMap::new()) };
}

/// Time spent in handlers on this thread, per actor kind (for `timing.json`; never read by a
/// handler, so it cannot make a run depend on the machine's speed).
pub fn busy_time() -> BTreeMap<&'static str, Duration> {
    BUSY.with(|b| b.borrow().clone())
}

/// Runs `body`; if it panics, logs, and stops `ctx`'s actor so that its supervisor restarts it.
/// Returns whether the body completed.
pub(crate) fn contained<A>(ctx: &mut Context<A>, actor: &'static str, body: impl FnOnce()) -> bool
where
    A: Actor<Context = Context<A>>,
{
    crate::quiescence::record_activity();
    let started = Instant::now();
    let outcome = catch_unwind(AssertUnwindSafe(body));
    BUSY.with(|b| *b.borrow_mut().entry(actor).or_default() += started.elapsed());
    match outcome {
        Ok(()) => true,
        Err(payload) => {
            tracing::error!(actor, "handler panicked ({}); message dropped, actor restarting", panic_text(&*payload));
            ctx.stop();
            false
        }
    }
}

fn panic_text(payload: &(dyn Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("a non-text panic payload")
}

#[cfg(test)]
mod tests {
    use super::*;
    use actix::{Handler, Message, Supervised, Supervisor};

    #[derive(Default)]
    struct Counter {
        count: u32,
        restarts: u32,
    }
    impl Actor for Counter {
        type Context = Context<Self>;
    }
    impl Supervised for Counter {
        fn restarting(&mut self, _: &mut Context<Self>) {
            self.restarts += 1;
        }
    }
    #[derive(Message)]
    #[rtype(result = "(u32, u32)")]
    struct Add(u32);
    impl Handler<Add> for Counter {
        type Result = actix::MessageResult<Add>;
        fn handle(&mut self, Add(n): Add, ctx: &mut Context<Self>) -> Self::Result {
            contained(ctx, "counter", || {
                assert!(n != 0, "zero is the bug");
                self.count += n;
            });
            actix::MessageResult((self.count, self.restarts))
        }
    }

    #[actix_rt::test]
    async fn a_panicking_handler_restarts_its_actor_with_its_state() {
        let counter = Supervisor::start(|_| Counter::default());
        assert_eq!(counter.send(Add(2)).await.ok(), Some((2, 0)));
        // The panic is caught: the reply still comes, then the actor stops and restarts.
        assert_eq!(counter.send(Add(0)).await.ok(), Some((2, 0)));
        assert_eq!(counter.send(Add(3)).await.ok(), Some((5, 1)));
    }

    #[test]
    fn panic_payloads_are_read_as_text() {
        assert_eq!(panic_text(&"static"), "static");
        assert_eq!(panic_text(&String::from("owned")), "owned");
        assert_eq!(panic_text(&7_u8), "a non-text panic payload");
    }
}
