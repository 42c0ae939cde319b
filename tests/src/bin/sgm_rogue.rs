//! A hostile node for `tests/ros_fleet.sh`: it can reach the ROS master but does not hold the
//! team key. It records the team topic, then for a while publishes forged envelopes (random
//! bytes) and replays of what it recorded on the team topic, calls every robot's Deliver service
//! with both, and — once the victim robot is down — registers the victim's Deliver service
//! itself and never answers a call. At the end it writes what it sent, per robot, as JSON, so
//! the test can check every bit of it was refused and counted.
//!
//! Usage: `sgm_rogue --robots 1,2,3,4 --victim 4 --record-s 15 --attack-s 30 --takeover-when FILE
//! --out COUNTS.json` (times in seconds of wall time from the start; the victim's service is
//! taken once FILE exists: the test creates it when it has killed the victim).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sgm_bridge::msg::sgm_msgs;
use sgm_bridge::transport::call::{deliver, service_address, CallTarget};
use sgm_bridge::transport::peers::{Locator, MasterLocator};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Envelopes recorded off the team topic: (claimed sender, bytes).
type Recorded = Vec<(u16, Vec<u8>)>;

struct Options {
    robots: Vec<u16>,
    victim: u16,
    record: Duration,
    attack: Duration,
    takeover_when: std::path::PathBuf,
    out: String,
}

fn options() -> Result<Options, String> {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.contains(":=")).collect();
    let get = |name: &str| -> Result<String, String> {
        let at = args.iter().position(|a| a == name).ok_or(format!("{name} missing"))?;
        args.get(at + 1).cloned().ok_or(format!("{name} needs a value"))
    };
    let secs = |name: &str| -> Result<Duration, String> {
        get(name)?.parse::<f64>().map(Duration::from_secs_f64).map_err(|e| format!("{name}: {e}"))
    };
    Ok(Options {
        robots: get("--robots")?
            .split(',')
            .map(|r| r.parse().map_err(|e| format!("--robots: {e}")))
            .collect::<Result<_, _>>()?,
        victim: get("--victim")?.parse().map_err(|e| format!("--victim: {e}"))?,
        record: secs("--record-s")?,
        attack: secs("--attack-s")?,
        takeover_when: get("--takeover-when")?.into(),
        out: get("--out")?,
    })
}

/// What the rogue sent and what got through, per robot.
#[derive(Default, serde::Serialize)]
struct Counts {
    recorded: usize,
    /// On the team topic: forged envelopes by the sender they claim, and replays by original
    /// sender.
    broadcast_forged_as: BTreeMap<u16, u64>,
    broadcast_replayed_from: BTreeMap<u16, u64>,
    /// Deliver calls a robot's service answered: forged, replayed.
    delivered_forged: BTreeMap<u16, u64>,
    delivered_replayed: BTreeMap<u16, u64>,
    /// Calls to its own service for the victim, never answered.
    calls_held: u64,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("sgm_rogue: {e}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), String> {
    let options = options()?;
    rosrust::try_init("sgm_rogue").map_err(|e| e.to_string())?;
    let started = Instant::now();
    let recorded: Arc<Mutex<Recorded>> = Arc::default();
    let sink = recorded.clone();
    let record_until = options.record;
    let _team_in = rosrust::subscribe("/sgm/team", 256, move |m: sgm_msgs::Envelope| {
        let mut r = sink.lock().unwrap_or_else(PoisonError::into_inner);
        if started.elapsed() < record_until && r.len() < 500 {
            r.push((m.from_robot, m.data));
        }
    })
    .map_err(|e| e.to_string())?;
    let team = rosrust::publish::<sgm_msgs::Envelope>("/sgm/team", 256).map_err(|e| e.to_string())?;
    let locator = MasterLocator::of_this_node()?;
    let held = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let mut counts = Counts::default();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut takeover = None;
    while started.elapsed() < options.record {
        std::thread::sleep(Duration::from_millis(100));
    }
    let recorded = std::mem::take(&mut *recorded.lock().unwrap_or_else(PoisonError::into_inner));
    counts.recorded = recorded.len();
    eprintln!("sgm_rogue: recorded {} envelopes", recorded.len());
    let attack_end = options.record + options.attack;
    let mut tick = 0usize;
    while started.elapsed() < attack_end && rosrust::is_ok() {
        if takeover.is_none() && options.takeover_when.exists() {
            let held = held.clone();
            let name = format!("/sgm/robot_{}/deliver", options.victim);
            let service = rosrust::service::<sgm_msgs::Deliver, _>(&name, move |_| {
                held.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                loop {
                    std::thread::sleep(Duration::from_secs(3600));
                }
            })
            .map_err(|e| e.to_string())?;
            eprintln!("sgm_rogue: serving {name}, never answering");
            takeover = Some(service);
        }
        tick += 1;
        // 10 a second on the team topic: a forgery and a replay.
        let forged: Vec<u8> = (0..rng.random_range(20..200)).map(|_| rng.random()).collect();
        let claimed = options.robots[tick % options.robots.len()];
        if team.send(sgm_msgs::Envelope { from_robot: claimed, data: forged.clone() }).is_ok() {
            *counts.broadcast_forged_as.entry(claimed).or_default() += 1;
        }
        if let Some((from, data)) = recorded.get(tick % recorded.len().max(1)) {
            if team.send(sgm_msgs::Envelope { from_robot: *from, data: data.clone() }).is_ok() {
                *counts.broadcast_replayed_from.entry(*from).or_default() += 1;
            }
        }
        // 2 a second to a robot's Deliver service: a forgery or a replay, alternately.
        if tick % 5 == 0 {
            let robot = options.robots[(tick / 5) % options.robots.len()];
            let replay = (tick / 5) % 2 == 1;
            let data = match recorded.get(tick % recorded.len().max(1)) {
                Some((from, data)) if replay && *from != robot => Some(data.clone()),
                _ if !replay => Some(forged),
                _ => None,
            };
            if let Some(data) = data.filter(|_| robot != options.victim || takeover.is_none()) {
                let name = format!("/sgm/robot_{robot}/deliver");
                let called = locator.lookup(&name).map_err(|e| e.to_string()).and_then(|uri| {
                    let target = CallTarget {
                        address: service_address(&uri).map_err(|e| e.to_string())?,
                        service: &name,
                        caller_id: "/sgm_rogue",
                        timeout: Duration::from_secs(2),
                        max_reply: 1 << 16,
                    };
                    deliver(&target, &sgm_msgs::DeliverReq { from_robot: robot, data }).map_err(|e| e.to_string())
                });
                if called.is_ok() {
                    let map = if replay { &mut counts.delivered_replayed } else { &mut counts.delivered_forged };
                    *map.entry(robot).or_default() += 1;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    counts.calls_held = held.load(std::sync::atomic::Ordering::Relaxed);
    let json = serde_json::to_string_pretty(&counts).map_err(|e| e.to_string())?;
    std::fs::write(&options.out, json).map_err(|e| format!("{}: {e}", options.out))?;
    eprintln!("sgm_rogue: done, {} calls held", counts.calls_held);
    drop(takeover);
    Ok(())
}
