//! A robot restored from its snapshot refuses what it may have accepted after the snapshot was
//! taken: envelopes recorded between the snapshot and a crash, replayed to the restored robot,
//! are all refused (the replay journal, `sgm_actors::journal`), while the sender's later ones
//! go through. Without the journal the restored windows would accept every one of them again.

use sgm_actors::clock::Clock;
use sgm_actors::comms::{AttachJournal, GetCommsStatus};
use sgm_actors::config::RobotConfig;
use sgm_actors::journal::{self, JournalFile};
use sgm_actors::quiescence::until_quiet;
use sgm_actors::supervisor::{start_robot, start_robot_restored};
use sgm_actors::transport::{InProcessRadio, PerfectLinks, Transport};
use sgm_model::scene_graph::{KeyframeId, RobotId};
use sgm_model::wire::messages::KeyframeRefusal;
use sgm_model::wire::messages::KeyframeRefusalReason;
use sgm_model::wire::{seal, Destination, Envelope, Message, Sequence, WireLimits, PROTOCOL_VERSION};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn config() -> RobotConfig {
    let mut c = RobotConfig::default();
    c.robot.id = 1;
    c.robot.name = "alpha".into();
    c
}

/// Robot 2's envelope number `counter` of incarnation 0x5EED: a refusal of nothing, which robot
/// 1 accepts and counts without any other consequence.
fn from_robot_2(counter: u64) -> Vec<u8> {
    let key = config().comms.team_key().unwrap();
    let envelope = Envelope {
        version: PROTOCOL_VERSION,
        from: RobotId(2),
        to: Destination::Robot(RobotId(1)),
        sequence: Sequence { incarnation: 0x5EED, counter }.to_bits(),
        message: Message::KeyframeRefusal(KeyframeRefusal {
            keyframes: vec![KeyframeId(0)],
            reason: KeyframeRefusalReason::Busy,
        }),
    };
    seal(&envelope, &key, &WireLimits::default()).unwrap()
}

async fn deliver(radio: &InProcessRadio, counters: impl Iterator<Item = u64>) {
    for c in counters {
        radio.transmit(RobotId(2), Destination::Robot(RobotId(1)), from_robot_2(c), 0.0);
    }
    radio.deliver_due(0.0);
    until_quiet().await;
}

#[actix_rt::test]
async fn envelopes_accepted_after_the_snapshot_are_refused_after_the_restore() {
    let dir = tempfile::tempdir().unwrap();
    let radio = InProcessRadio::new(Box::new(PerfectLinks));
    let handle = start_robot(&config(), Clock::starting_at(0.0), &radio).unwrap();
    let journal = JournalFile::start(dir.path(), "alpha");
    let journal_path = journal.path().to_path_buf();
    handle.comms.do_send(AttachJournal(Arc::new(journal)));
    deliver(&radio, 1..=10).await;
    let mut snapshot = handle.freeze().await.unwrap();
    // After the snapshot: 50 more, recorded by an eavesdropper; then the robot crashes.
    deliver(&radio, 11..=60).await;
    let status = handle.comms.send(GetCommsStatus).await.unwrap();
    assert_eq!(status.rejected.replayed, 0);
    // The journal's writer has had time to land the reservation for counter 60.
    let deadline = Instant::now() + Duration::from_secs(10);
    while JournalFile::load(&journal_path).unwrap().is_none_or(|r| r.entries.first().is_none_or(|e| e.2 <= 60)) {
        assert!(Instant::now() < deadline, "the journal never reserved past counter 60");
        std::thread::sleep(Duration::from_millis(10));
    }
    handle.halt();
    radio.detach(RobotId(1));

    assert!(journal::apply(&mut snapshot.comms.replay, &journal_path).unwrap() > 0);
    let restored = start_robot_restored(
        &config(),
        Clock::starting_at(0.0),
        Box::new(radio.clone()),
        |r, c| radio.attach(r, c.recipient()),
        Some(snapshot),
        0,
        sgm_model::workers::Workers::sequential(),
    )
    .unwrap();
    until_quiet().await;
    let before = restored.comms.send(GetCommsStatus).await.unwrap().rejected.replayed;
    deliver(&radio, 11..=60).await;
    let status = restored.comms.send(GetCommsStatus).await.unwrap();
    assert_eq!(status.rejected.replayed - before, 50, "every recorded envelope refused");
    // The sender goes on (its counter past the reservation): heard again.
    let received = status.received.bytes_total();
    deliver(&radio, 200..=201).await;
    let status = restored.comms.send(GetCommsStatus).await.unwrap();
    assert!(status.received.bytes_total() > received, "the sender's later envelopes are accepted");
}

/// Keeps what the robot sends.
#[derive(Clone, Default)]
struct Recorder(Arc<std::sync::Mutex<Vec<Vec<u8>>>>);

impl Transport for Recorder {
    fn transmit(&self, _: RobotId, _: Destination, bytes: Vec<u8>, _: f64) {
        self.0.lock().unwrap().push(bytes);
    }
}

/// A neighbour heard under a new incarnation may have been restored with a replay journal:
/// what we send next skips past its reservation, so it is heard at once.
#[actix_rt::test]
async fn a_restarted_neighbour_makes_our_counter_skip_past_its_reservation() {
    use sgm_model::wire::messages::KeyframeRequest;
    use sgm_model::wire::replay::RESERVE;
    let recorder = Recorder::default();
    let mut comms = None;
    let handle = sgm_actors::supervisor::start_robot_on(
        &config(),
        Clock::starting_at(0.0),
        Box::new(recorder.clone()),
        |_, c| comms = Some(c),
    )
    .unwrap();
    let key = config().comms.team_key().unwrap();
    let ask = |incarnation| {
        let envelope = Envelope {
            version: PROTOCOL_VERSION,
            from: RobotId(2),
            to: Destination::Robot(RobotId(1)),
            sequence: Sequence { incarnation, counter: 1 }.to_bits(),
            message: Message::KeyframeRequest(KeyframeRequest { keyframes: vec![KeyframeId(99)] }),
        };
        sgm_actors::transport::Delivered { bytes: seal(&envelope, &key, &WireLimits::default()).unwrap() }
    };
    let tick = |t| sgm_actors::messages::Tick { now: t };
    let sent_counters = || -> Vec<u64> {
        let limits = WireLimits::default();
        recorder.0.lock().unwrap().iter().map(|b| sgm_model::wire::open(b, &key, &limits).unwrap().sequence).collect()
    };
    handle.comms.do_send(ask(0xA));
    until_quiet().await;
    handle.supervisor.do_send(tick(1.0));
    until_quiet().await;
    let before = *sent_counters().last().expect("robot 1 answered");
    handle.comms.do_send(ask(0xB));
    until_quiet().await;
    handle.supervisor.do_send(tick(2.0));
    until_quiet().await;
    let after = *sent_counters().last().unwrap();
    assert!(after > before + RESERVE, "{before} then {after}: no skip past the reservation");
    drop(comms);
}
