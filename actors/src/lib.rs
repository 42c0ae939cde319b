//! One robot as a tree of actix actors (DESIGN.md §3) and the SGM exchange between robots
//! (paper §IV-B..F):
//!
//! ```text
//! RobotSupervisor ─┬─ Sensor ─► Fusion ─► Tracker ─┬─► Optimiser ─► (Tracker, Matcher)
//!                  │                               ├─► Matcher ◄──► Comms ◄──► other robots
//!                  │                               └─► Comms
//! ```

/// The [`messages::InjectFailure`] handler of each listed actor: it stops, or panics inside
/// [`containment::contained`] under the actor's handler name; either way its actix `Supervisor`
/// restarts it with its state.
macro_rules! stops_on_injected_failure {
    ($($actor:ty => $name:literal),*) => {$(
        impl actix::Handler<crate::messages::InjectFailure> for $actor {
            type Result = ();
            fn handle(&mut self, failure: crate::messages::InjectFailure, ctx: &mut actix::Context<Self>) {
                match failure {
                    crate::messages::InjectFailure::Stop => actix::ActorContext::stop(ctx),
                    crate::messages::InjectFailure::Panic => {
                        crate::containment::contained(ctx, $name, || panic!("injected failure"));
                    }
                }
            }
        }
    )*};
}

/// The [`messages::Connect`] and [`messages::Halt`] handlers of each listed actor and links type.
macro_rules! connects {
    ($($actor:ty => $links:ty),*) => {$(
        impl actix::Handler<crate::messages::Connect<$links>> for $actor {
            type Result = ();
            fn handle(&mut self, msg: crate::messages::Connect<$links>, _: &mut actix::Context<Self>) {
                self.links = Some(msg.0);
            }
        }

        impl actix::Handler<crate::messages::Halt> for $actor {
            type Result = ();
            fn handle(&mut self, _: crate::messages::Halt, _: &mut actix::Context<Self>) {
                self.links = None;
            }
        }
    )*};
}

/// The [`messages::Freeze`] handler of each listed actor and its state type: the actor's
/// `freeze()`.
macro_rules! freezes {
    ($($actor:ty => $state:ty),*) => {$(
        impl actix::Handler<crate::messages::Freeze<$state>> for $actor {
            type Result = actix::MessageResult<crate::messages::Freeze<$state>>;
            fn handle(&mut self, _: crate::messages::Freeze<$state>, _: &mut actix::Context<Self>) -> Self::Result {
                actix::MessageResult(self.freeze())
            }
        }
    )*};
}

pub mod clock;
pub mod comms;
pub mod config;
pub mod containment;
pub mod fusion;
pub mod journal;
pub mod map_view;
pub mod matcher;
pub mod messages;
pub mod odometry;
pub mod optimiser;
pub mod progress;
pub mod protocol;
pub mod quiescence;
pub mod sensor;
pub mod snapshot;
pub mod supervisor;
pub mod tracker;
pub mod transport;
