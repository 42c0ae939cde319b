//! What the tests that start `sgm ros` processes share: polling, an embedded ROS master
//! (`ros-core-rs`: no ROS installation needed), and the nodes and topics (`nodes.rs`).

pub mod nodes;

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

/// Polls `found` every 20 ms until it gives a value; fails with `what()` after `secs`.
pub fn poll<T>(secs: u64, what: impl Fn() -> String, mut found: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(value) = found() {
            return value;
        }
        assert!(Instant::now() < deadline, "timed out: {}", what());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Starts a ROS master on a free loopback port, in a thread that lives as long as the test.
pub fn embedded_master() -> SocketAddr {
    let addr = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a free port");
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build()?;
        runtime.block_on(ros_core_rs::core::Master::new(&addr).serve())
    });
    poll(10, || format!("the embedded master did not come up on {addr}"), || TcpStream::connect(addr).ok());
    addr
}
