//! The `sgm ros` processes a test starts, and the topics it feeds and reads: bags' messages
//! published as recorded, the newest message of an output, each node's status.
#![allow(dead_code)]

use super::poll;
use rosrust::RosMsg;
use serde_json::Value;
use sgm_bridge::msg::{nav_msgs, sensor_msgs, std_msgs, tf2_msgs};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};

/// A fresh team key in `dir/team.key` (mode 600), as the book's command makes one.
pub fn team_key_file(dir: &Path) -> PathBuf {
    use std::io::{Read, Write};
    use std::os::unix::fs::OpenOptionsExt;
    let mut bytes = [0u8; 32];
    std::fs::File::open("/dev/urandom").and_then(|mut f| f.read_exact(&mut bytes)).expect("/dev/urandom");
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    let path = dir.join("team.key");
    let mut file = std::fs::OpenOptions::new().write(true).create_new(true).mode(0o600).open(&path).expect("team.key");
    writeln!(file, "{hex}").expect("team.key written");
    path
}

/// The `sgm ros` processes; killed if the test fails.
pub struct Nodes {
    children: Vec<(String, Child, PathBuf)>,
}

impl Nodes {
    /// Starts `robots` of quickstart, each keeping its snapshots in `dir/snapshots` (and resuming
    /// from one there), with `env`'s settings besides; `run` tells the log files of successive
    /// starts apart.
    pub fn start(master: SocketAddr, dir: &Path, robots: &[&str], run: u32, env: &[(&str, &str)]) -> Self {
        let children = robots
            .iter()
            .map(|robot| {
                let log = dir.join(format!("{robot}.{run}.log"));
                let child = Command::new(env!("CARGO_BIN_EXE_sgm"))
                    .args(["ros", "--robot", robot, "--scenario", "quickstart", &format!("__ns:=/{robot}")])
                    .env("SGM__PERSISTENCE__DIRECTORY", dir.join("snapshots"))
                    .env("SGM__COMMS__TEAM_KEY_FILE", dir.join("team.key"))
                    .env("ROS_MASTER_URI", format!("http://{master}"))
                    .env("ROS_IP", "127.0.0.1")
                    .env("ROS_HOME", dir)
                    .env("RUST_LOG", "info")
                    .envs(env.iter().copied())
                    .env_remove("ROS_HOSTNAME")
                    .env_remove("ROS_NAMESPACE")
                    .stdout(Stdio::null())
                    .stderr(std::fs::File::create(&log).expect("log file"))
                    .spawn()
                    .expect("sgm ros starts");
                (robot.to_string(), child, log)
            })
            .collect();
        Self { children }
    }

    pub fn log(&self, robot: &str) -> String {
        let (_, _, path) = self.children.iter().find(|(r, _, _)| r == robot).expect("a robot");
        std::fs::read_to_string(path).unwrap_or_default()
    }

    pub fn running(&mut self, robot: &str) -> bool {
        let (_, child, _) = self.children.iter_mut().find(|(r, _, _)| r == robot).expect("a robot");
        matches!(child.try_wait(), Ok(None))
    }

    /// SIGINT to each node; each must exit with success.
    pub fn interrupt(mut self) {
        for (robot, child, _) in &mut self.children {
            let sent = Command::new("kill").args(["-INT", &child.id().to_string()]).status();
            assert!(sent.is_ok_and(|s| s.success()), "SIGINT to {robot}");
        }
        for (robot, child, _) in &mut self.children {
            let status = poll(20, || format!("{robot} did not exit on SIGINT"), || child.try_wait().ok().flatten());
            assert!(status.success(), "{robot} exited with {status} on SIGINT");
        }
        self.children.clear();
    }
}

impl Drop for Nodes {
    fn drop(&mut self) {
        for (robot, child, log) in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
            if std::thread::panicking() {
                eprintln!(
                    "--- {robot}'s log ({}):\n{}",
                    log.display(),
                    std::fs::read_to_string(&*log).unwrap_or_default()
                );
            }
        }
    }
}

/// The newest message of a topic.
pub struct Latest<T> {
    value: Arc<Mutex<Option<T>>>,
    _subscriber: rosrust::Subscriber,
}

impl<T: rosrust::Message> Latest<T> {
    pub fn subscribe(topic: &str) -> Self {
        let value = Arc::new(Mutex::new(None));
        let sink = value.clone();
        let subscriber =
            rosrust::subscribe(topic, 10, move |m: T| *sink.lock().unwrap() = Some(m)).expect("subscribes");
        Self { value, _subscriber: subscriber }
    }

    pub fn get(&self) -> Option<T> {
        self.value.lock().unwrap().clone()
    }

    /// Waits (at most `secs`) for a message `ok` accepts; `what` names it on failure.
    pub fn wait_for(&self, secs: u64, what: &str, ok: impl Fn(&T) -> bool) -> T {
        poll(secs, || format!("waiting for {what}"), || self.get().filter(|m| ok(m)))
    }
}

/// Each node's status topic, parsed.
pub struct Statuses(Vec<(String, Latest<std_msgs::String>)>);

impl Statuses {
    pub fn subscribe(robots: &[&str]) -> Self {
        Self(robots.iter().map(|r| (r.to_string(), Latest::subscribe(&format!("/{r}/sgm/status")))).collect())
    }

    pub fn of(&self, robot: &str) -> Option<Value> {
        let (_, latest) = self.0.iter().find(|(r, _)| r == robot)?;
        serde_json::from_str(&latest.get()?.data).ok()
    }

    pub fn wait_for(&self, robot: &str, secs: u64, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
        let last = || format!("waiting for {robot}'s {what}; last status: {:?}", self.of(robot));
        poll(secs, last, || self.of(robot).filter(|s| ok(s)))
    }

    pub fn aligned(status: &Value) -> bool {
        status["neighbours"].as_array().is_some_and(|n| !n.is_empty() && n.iter().all(|n| n["state"] == "Aligned"))
    }
}

/// A sensor topic's publisher.
pub enum Feed {
    Cloud(rosrust::Publisher<sensor_msgs::PointCloud2>),
    Image(rosrust::Publisher<sensor_msgs::Image>),
    CameraInfo(rosrust::Publisher<sensor_msgs::CameraInfo>),
    Odometry(rosrust::Publisher<nav_msgs::Odometry>),
    Imu(rosrust::Publisher<sensor_msgs::Imu>),
    /// The mounts (`/tf_static`, latched as tf2's static broadcaster publishes them).
    Tf(rosrust::Publisher<tf2_msgs::TFMessage>),
}

impl Feed {
    pub fn advertise(topic: &str) -> Option<Self> {
        let q = 100;
        Some(match topic.rsplit('/').next()? {
            "points" => Feed::Cloud(rosrust::publish(topic, q).expect("advertises")),
            "labels" => Feed::Image(rosrust::publish(topic, q).expect("advertises")),
            "camera_info" => Feed::CameraInfo(rosrust::publish(topic, q).expect("advertises")),
            "odometry" => Feed::Odometry(rosrust::publish(topic, q).expect("advertises")),
            "imu" => Feed::Imu(rosrust::publish(topic, 1000).expect("advertises")),
            "tf_static" => {
                let mut publisher = rosrust::publish(topic, q).expect("advertises");
                publisher.set_latching(true);
                Feed::Tf(publisher)
            }
            _ => return None,
        })
    }

    pub fn subscribers(&self) -> usize {
        match self {
            Feed::Cloud(p) => p.subscriber_count(),
            Feed::Image(p) => p.subscriber_count(),
            Feed::CameraInfo(p) => p.subscriber_count(),
            Feed::Odometry(p) => p.subscriber_count(),
            Feed::Imu(p) => p.subscriber_count(),
            Feed::Tf(p) => p.subscriber_count(),
        }
    }

    /// Publishes a message recorded in a bag.
    pub fn send(&self, data: &[u8]) {
        let sent = match self {
            Feed::Cloud(p) => p.send(RosMsg::decode(data).expect("bag cloud")),
            Feed::Image(p) => p.send(RosMsg::decode(data).expect("bag image")),
            Feed::CameraInfo(p) => p.send(RosMsg::decode(data).expect("bag camera info")),
            Feed::Odometry(p) => p.send(RosMsg::decode(data).expect("bag odometry")),
            Feed::Imu(p) => p.send(RosMsg::decode(data).expect("bag imu")),
            Feed::Tf(p) => p.send(RosMsg::decode(data).expect("bag tf")),
        };
        sent.expect("publishes");
    }
}

/// Publishes `messages` (from [`bag_messages`]) on their feeds, `rate` times faster than they
/// were recorded; after each, `after(topic)` may stop the playback by returning true.
pub fn play(
    messages: &[(u64, String, Vec<u8>)],
    feeds: &BTreeMap<String, Feed>,
    rate: f64,
    mut after: impl FnMut(&str) -> bool,
) {
    let Some((t0, _, _)) = messages.first() else { return };
    let wall0 = std::time::Instant::now();
    for (time, topic, data) in messages {
        let Some(feed) = feeds.get(topic) else { continue };
        let due = wall0 + std::time::Duration::from_secs_f64((time - t0) as f64 * 1e-9 / rate);
        std::thread::sleep(due.saturating_duration_since(std::time::Instant::now()));
        feed.send(data);
        if after(topic) {
            break;
        }
    }
}

/// Every message of `bags` as (record time ns, topic, bytes), in record-time order.
pub fn bag_messages(bags: &[PathBuf]) -> Vec<(u64, String, Vec<u8>)> {
    let mut all = Vec::new();
    for path in bags {
        let bag = rosbag::RosBag::new(path).expect("bag opens");
        let mut topics = BTreeMap::new();
        for record in bag.chunk_records() {
            let rosbag::ChunkRecord::Chunk(chunk) = record.expect("chunk") else { continue };
            for message in chunk.messages() {
                match message.expect("message") {
                    rosbag::MessageRecord::Connection(c) => {
                        topics.insert(c.id, c.topic.to_string());
                    }
                    rosbag::MessageRecord::MessageData(m) => {
                        all.push((m.time, topics[&m.conn_id].clone(), m.data.to_vec()));
                    }
                }
            }
        }
    }
    all.sort_by_key(|m| m.0);
    all
}
