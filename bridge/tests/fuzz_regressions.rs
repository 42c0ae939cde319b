//! Every input a fuzz target crashed on (`fuzz/README.md`), kept in `tests/fuzz_regressions/`
//! and fed again to what the node decodes ROS messages with. The first, found by fuzzing
//! rosrust's own decoder, is 41 bytes of PointCloud2 whose `data` declares 4 143 379 968
//! bytes: rosrust reserved them before reading (an abort under the fuzzer's malloc limit).
//! Through `Bounded` every one is refused by name and allocates nothing of the sort.
//!
//! The inputs of the `rosbag` and `tcpros_reply` targets are kept in `fuzz/regressions/` and
//! read here through the replay's bag reader and the TCPROS client's reply reader, with the
//! largest single allocation measured (this test binary's allocator records it).

use rosrust::RosMsg;
use sgm_bridge::bag::reader::{read_bag, BagItem, BagSource};
use sgm_bridge::bounded::{Bounded, Layout};
use sgm_bridge::bounded_deliver::BoundedDeliverReq;
use sgm_bridge::config::{RosConfig, DEFAULT_MAX_MESSAGE_BYTES};
use sgm_bridge::msg::{nav_msgs, sensor_msgs, sgm_msgs};
use sgm_bridge::transport::call::read_reply;
use std::alloc::{GlobalAlloc, Layout as AllocLayout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The system allocator, recording the largest single request while [`largest_allocation`] runs.
struct Recording;

static LARGEST: AtomicUsize = AtomicUsize::new(0);
/// One measurement at a time (the tests of this binary run in parallel).
static MEASURING: Mutex<()> = Mutex::new(());

unsafe impl GlobalAlloc for Recording {
    unsafe fn alloc(&self, layout: AllocLayout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: AllocLayout) {
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: AllocLayout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: AllocLayout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Recording = Recording;

/// What `f` returns, and the largest single allocation made meanwhile (by any thread).
fn largest_allocation<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let _one = MEASURING.lock().unwrap_or_else(|e| e.into_inner());
    LARGEST.store(0, Ordering::Relaxed);
    let out = f();
    (out, LARGEST.load(Ordering::Relaxed))
}

/// Each input kept in `fuzz/regressions/TARGET/`, with its path.
fn regressions(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/regressions").join(target);
    let mut inputs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            (path, bytes)
        })
        .collect();
    inputs.sort();
    assert!(!inputs.is_empty(), "{}", dir.display());
    inputs
}

fn refused<M: RosMsg + Layout>(framed: &[u8]) -> Option<String> {
    Bounded::<M>::decode_slice(framed).err().map(|e| e.to_string())
}

#[test]
fn every_crash_input_is_refused_without_a_large_allocation() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions");
    let mut inputs: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    inputs.sort();
    assert!(!inputs.is_empty());
    for path in inputs {
        let data = std::fs::read(&path).unwrap();
        // As the fuzz target frames it: TCPROS's length prefix, then the message.
        let mut framed = (data.len() as u32).to_le_bytes().to_vec();
        framed.extend_from_slice(&data);
        let cloud = refused::<sensor_msgs::PointCloud2>(&framed);
        if path.file_name().is_some_and(|n| n.to_string_lossy().starts_with("ros_pointcloud2")) {
            assert!(cloud.as_deref().is_some_and(|e| e.contains("needs")), "{}: {cloud:?}", path.display());
        }
        // Every subscribed type decodes or refuses it; none panics or aborts.
        let _ = refused::<sensor_msgs::Image>(&framed);
        let _ = refused::<sensor_msgs::CameraInfo>(&framed);
        let _ = refused::<nav_msgs::Odometry>(&framed);
        let _ = refused::<sgm_msgs::Envelope>(&framed);
        let _ = BoundedDeliverReq::decode_slice(&framed);
    }
}

/// Bags the `rosbag` target stopped on, and one made by hand beside them. The reader (then the
/// `rosbag` crate) sliced its file at the header's `index_pos` and panicked on its thread when
/// that lay beyond the end (`index_pos_beyond_the_end`, found in the first seconds) or before
/// the first record (`index_pos_zero_recording_cut_off`: what a recording that was killed
/// leaves), and reserved the uncompressed size a chunk declares (`bz2_chunk_declares_4_gb`, an
/// 11 KB bag that asked for 4 GB). Each now ends with one failure that says why, having
/// allocated no more than the bag's size.
#[test]
fn bags_the_fuzzer_stopped_on_fail_by_name_within_their_size() {
    let expected = [
        ("bz2_chunk_declares_4_gb", "a chunk at byte 4117 declares 4026531840 bytes, at most"),
        ("index_pos_beyond_the_end", "index_pos 16320 is outside the file"),
        ("index_pos_zero_recording_cut_off", "index_pos 0 is outside the file"),
    ];
    let inputs = regressions("rosbag");
    assert_eq!(inputs.len(), expected.len());
    for ((path, bytes), (name, error)) in inputs.iter().zip(expected) {
        assert!(path.ends_with(name), "{}", path.display());
        let (items, largest) = largest_allocation(|| {
            read_bag(path, BagSource::new(&RosConfig::default(), "alpha", 1)).into_iter().collect::<Vec<_>>()
        });
        match items.last() {
            Some(BagItem::Failed(e)) => assert!(e.to_string().contains(error), "{}: {e}", path.display()),
            other => panic!("{}: ends with {other:?}, a failure expected", path.display()),
        }
        assert!(largest <= bytes.len().max(1 << 16), "{}: allocated {largest} bytes at once", path.display());
    }
}

/// Replies the `tcpros_reply` target stopped on. A 110-byte reply declared 117 MB and the
/// client reserved them before reading one (up to `ros.max_message_bytes`, 128 MiB, per call
/// to a hostile peer). The buffer now grows as bytes arrive.
#[test]
fn replies_the_fuzzer_stopped_on_cost_what_they_sent() {
    for (path, bytes) in regressions("tcpros_reply") {
        let (result, largest) = largest_allocation(|| read_reply(&mut &bytes[..], DEFAULT_MAX_MESSAGE_BYTES));
        assert!(result.is_err(), "{}", path.display());
        assert!(largest <= 1 << 16, "{}: allocated {largest} bytes at once", path.display());
    }
}
