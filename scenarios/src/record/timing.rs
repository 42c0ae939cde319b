//! Wall-clock facts of a run, kept apart from the report so that the report stays
//! deterministic (`timing.json`).

use crate::memory::{resident_mb, MemorySample};
use std::time::{Duration, Instant};

/// Wall-clock facts of a run: kept out of the report so that the report is deterministic.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timing {
    pub wall_s: f64,
    pub sim_s: f64,
    pub realtime_factor: f64,
    /// Time in handlers per actor kind, summed over the robots' threads, s (CPU time, when
    /// the threads did not outnumber the cores).
    pub actor_busy_s: std::collections::BTreeMap<String, f64>,
    /// Time producing sensor frames (simulating, or reading and decoding bags), s.
    pub simulation_s: f64,
    /// The part of it the robots waited for, s: all of it when the frames are made on the
    /// runner's thread (one thread, bag replay). With more threads the sensors are simulated up
    /// to four steps ahead on otherwise idle cores, and only what did not fit there is waited
    /// for; `simulation_s` is then the wall time of a thread that yields to the robots, longer
    /// than the same work on one thread.
    pub simulation_waited_s: f64,
    /// Resident memory at every observation, and its peak over the run, MiB (Linux).
    pub memory: Vec<MemorySample>,
    pub peak_resident_mb: Option<f64>,
}

impl Timing {
    /// `(simulation, waited)`: time producing sensor frames, and the part of it waited for;
    /// `actor_busy`: time in handlers per actor kind, summed over the robots' threads.
    pub fn measure(
        wall: Instant,
        sim_s: f64,
        (simulation, waited): (Duration, Duration),
        memory: Vec<MemorySample>,
        actor_busy: std::collections::BTreeMap<&'static str, Duration>,
    ) -> Self {
        let wall_s = wall.elapsed().as_secs_f64();
        Self {
            memory,
            peak_resident_mb: resident_mb().1,
            wall_s,
            sim_s,
            realtime_factor: sim_s / wall_s.max(1e-9),
            actor_busy_s: actor_busy.into_iter().map(|(k, v)| (k.to_string(), v.as_secs_f64())).collect(),
            simulation_s: simulation.as_secs_f64(),
            simulation_waited_s: waited.as_secs_f64(),
        }
    }
}
