//! What rosrust (0.9) reserves from a length a peer declares, measured by the largest single
//! allocation while it decodes a few bytes that declare far more. The book's ROS chapter
//! ("Bounded decoding") names what stays out of the node's reach; this keeps it true when
//! rosrust changes.
//!
//! One test in its own binary: the allocator below records every allocation in the process.

use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::HashMap;
use std::io::Cursor;
use std::sync::atomic::{AtomicUsize, Ordering};

use rosrust::RosMsg;

/// The system allocator, remembering the largest request since the last [`largest_since`].
struct Recording;

static LARGEST: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Recording {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LARGEST.fetch_max(layout.size(), Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LARGEST.fetch_max(new_size, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static ALLOCATOR: Recording = Recording;

/// The largest allocation `f` asked for.
fn largest_since<T>(f: impl FnOnce() -> T) -> (T, usize) {
    LARGEST.store(0, Ordering::Relaxed);
    let out = f();
    (out, LARGEST.load(Ordering::Relaxed))
}

const MIB: usize = 1 << 20;

#[test]
fn headers_grow_as_bytes_arrive_and_primitive_arrays_reserve_their_declared_length() {
    // A TCPROS connection header: its size and its one string each declare 4 GiB - 1; 3 bytes follow.
    let mut header = vec![0xff; 8];
    header.extend_from_slice(b"a=b");
    let (decoded, largest) = largest_since(|| <HashMap<String, String>>::decode(Cursor::new(&header)));
    assert!(largest < MIB, "the header decoder asked for {largest} bytes");
    // Cut short, the string is dropped; rosrust then refuses the connection for missing fields.
    assert_eq!(decoded.map(|fields| fields.len()).ok(), Some(0));

    // The failure string a service caller decodes: the same String decoder.
    let (decoded, largest) = largest_since(|| String::decode(Cursor::new(&header[4..])));
    assert!(largest < MIB, "the string decoder asked for {largest} bytes");
    assert!(decoded.is_err());

    // A uint8[] field (PointCloud2's `data`) declaring 256 MiB with 3 bytes behind it: rosrust
    // reserves the whole of it first, which is why the node decodes through `bounded.rs`.
    let declared: u32 = 256 << 20;
    let mut array = declared.to_le_bytes().to_vec();
    array.extend_from_slice(b"abc");
    let (decoded, largest) =
        largest_since(|| rosrust::rosmsg::decode_variable_primitive_vec::<_, u8>(Cursor::new(&array)));
    assert!(decoded.is_err());
    assert!(
        largest >= declared as usize,
        "rosrust no longer reserves a declared array ({largest} bytes); update ros.md"
    );
}
