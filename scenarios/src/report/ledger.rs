//! The report's accounting: proof that nothing was lost. For each robot, what its map holds and
//! which ObjectData revision it last sent; for each ordered pair, whether the receiver holds
//! that revision and what became of every keyframe it wanted (`wanted = received + refused +
//! given up + pending`, each id counted once); for each crash, what the snapshot carried over
//! and whether the final map still holds every keyframe of it.

use crate::observation::Observation;
use crate::record::RunRecord;
use serde::Serialize;

#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Ledger {
    pub robots: Vec<RobotLedger>,
    pub pairs: Vec<PairLedger>,
    pub restarts: Vec<RestartLedger>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotLedger {
    pub name: String,
    pub keyframes: usize,
    pub objects: usize,
    /// ObjectData revision last broadcast (0: none).
    pub object_data_revision: u32,
}

/// What `local` holds of `remote`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairLedger {
    pub local: String,
    pub remote: String,
    /// Revision of the remote's ObjectData held (`None`: none arrived).
    pub object_data_revision: Option<u32>,
    /// It is the remote's latest.
    pub object_data_current: bool,
    pub keyframes_wanted: u64,
    pub keyframes_received: u64,
    pub keyframes_refused: u64,
    pub keyframes_given_up: u64,
    pub keyframes_pending: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RestartLedger {
    pub robot: String,
    pub crashed_at_s: f64,
    pub restarted_at_s: f64,
    pub snapshot_taken_at_s: Option<f64>,
    pub keyframes_at_crash: usize,
    pub keyframes_in_snapshot: usize,
    pub objects_in_snapshot: usize,
    /// Keyframes of the snapshot still in the robot's map at the end (all of them, or
    /// something was lost).
    pub snapshot_keyframes_kept: usize,
}

pub fn compute(record: &RunRecord, last: &Observation) -> Ledger {
    let names: Vec<&str> = record.robots.iter().map(|r| r.name.as_str()).collect();
    let mut ledger = Ledger::default();
    let sent: Vec<u32> =
        last.maps.iter().map(|m| m.as_ref().map_or(0, |(_, _, comms)| comms.object_data_revision)).collect();
    for (k, map) in last.maps.iter().enumerate() {
        let Some((map, neighbours, comms)) = map else { continue };
        ledger.robots.push(RobotLedger {
            name: names[k].to_string(),
            keyframes: map.keyframes.len(),
            objects: map.objects.len(),
            object_data_revision: comms.object_data_revision,
        });
        for n in neighbours {
            let Some(j) = n.robot.index() else { continue };
            let Some(remote) = names.get(j) else { continue };
            let keyframes = comms.keyframe_ledger.get(&n.robot).cloned().unwrap_or_default();
            ledger.pairs.push(PairLedger {
                local: names[k].to_string(),
                remote: remote.to_string(),
                object_data_revision: n.objects_revision,
                object_data_current: n.objects_revision.is_some_and(|r| Some(&r) == sent.get(j)),
                keyframes_wanted: keyframes.wanted,
                keyframes_received: keyframes.received,
                keyframes_refused: keyframes.refused,
                keyframes_given_up: keyframes.given_up,
                keyframes_pending: keyframes.pending,
            });
        }
    }
    for restart in &record.restarts {
        let k = names.iter().position(|n| *n == restart.robot);
        let kept = k
            .and_then(|k| record.final_keyframes.get(k))
            .map_or(0, |ids| restart.snapshot_keyframes.iter().filter(|id| ids.contains(id)).count());
        ledger.restarts.push(RestartLedger {
            robot: restart.robot.clone(),
            crashed_at_s: restart.crashed_at,
            restarted_at_s: restart.restarted_at,
            snapshot_taken_at_s: restart.snapshot_taken_at,
            keyframes_at_crash: restart.keyframes_at_crash,
            keyframes_in_snapshot: restart.keyframes_in_snapshot,
            objects_in_snapshot: restart.objects_in_snapshot,
            snapshot_keyframes_kept: kept,
        });
    }
    ledger
}
