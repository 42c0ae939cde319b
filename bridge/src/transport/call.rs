//! One call of a peer's `sgm_msgs/Deliver` service over TCPROS, bounded in time and in bytes.
//!
//! rosrust's service client retries a refused connect 15 times with doubling pauses (about
//! 33 s) and never times out a read, so a peer that crashed, left radio range or never answers
//! holds the caller for half a minute or forever. This client speaks the same protocol
//! (ROS wiki, "ROS/TCPROS": a connection header of `key=value` fields both ways, then the
//! request as `u32 length ‖ message`, the reply as `u8 ok ‖ u32 length ‖ message`) with one
//! deadline for the whole call: connect, every write and every read get what is left of it.
//! Lengths the peer declares are checked before anything is reserved: a header beyond
//! [`MAX_HEADER_BYTES`], a reply beyond `max_reply` is refused.

use super::locator::LocatorError;
use crate::msg::sgm_msgs;
use rosrust::{Message, RosMsg};
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

/// Largest connection header accepted from a peer, bytes.
pub const MAX_HEADER_BYTES: usize = 64 << 10;

/// Why a call failed.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    #[error("`{0}` is not a rosrpc://host:port address")]
    Address(String),
    #[error("no answer within {0:?}")]
    Timeout(Duration),
    #[error("{0}")]
    Io(#[from] io::Error),
    #[error("the peer's header {0}")]
    Header(String),
    #[error("the peer declares a {what} of {len} bytes, at most {max} accepted")]
    TooLarge { what: &'static str, len: usize, max: usize },
    #[error("the service refused the call: {0}")]
    Refused(String),
    /// The peer's service was not located.
    #[error("{0}")]
    Lookup(#[from] LocatorError),
}

impl CallError {
    fn io(e: io::Error, timeout: Duration) -> Self {
        match e.kind() {
            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => Self::Timeout(timeout),
            _ => Self::Io(e),
        }
    }
}

/// A deadline every socket operation of one call shares.
struct Deadline {
    end: Instant,
    total: Duration,
}

impl Deadline {
    fn left(&self) -> Result<Duration, CallError> {
        let left = self.end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            Err(CallError::Timeout(self.total))
        } else {
            Ok(left)
        }
    }
}

/// A stream whose every read and write waits at most until the deadline.
struct Bounded<'a> {
    stream: TcpStream,
    deadline: &'a Deadline,
}

impl Bounded<'_> {
    fn write_all(&mut self, bytes: &[u8]) -> Result<(), CallError> {
        let mut at = 0;
        while at < bytes.len() {
            self.stream.set_write_timeout(Some(self.deadline.left()?))?;
            match self.stream.write(&bytes[at..]) {
                Ok(0) => return Err(CallError::Io(io::ErrorKind::WriteZero.into())),
                Ok(n) => at += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(CallError::io(e, self.deadline.total)),
            }
        }
        Ok(())
    }
}

/// Each read waits at most what is left of the deadline; past it, `TimedOut`.
impl Read for Bounded<'_> {
    fn read(&mut self, buffer: &mut [u8]) -> io::Result<usize> {
        let left = self.deadline.left().map_err(|_| io::Error::from(io::ErrorKind::TimedOut))?;
        self.stream.set_read_timeout(Some(left))?;
        self.stream.read(buffer)
    }
}

fn read_u32(stream: &mut impl Read) -> Result<u32, CallError> {
    let mut b = [0u8; 4];
    stream.read_exact(&mut b)?;
    Ok(u32::from_le_bytes(b))
}

/// A u32 length, then that many bytes: at most `max`, refused before reading otherwise. The
/// buffer grows as the bytes arrive (the `tcpros_reply` fuzz target found a 110-byte reply
/// that declared 117 MB, reserved before reading), so a peer costs what it sent.
fn read_counted(stream: &mut impl Read, what: &'static str, max: usize) -> Result<Vec<u8>, CallError> {
    let declared = read_u32(stream)?;
    let len = usize::try_from(declared).unwrap_or(usize::MAX);
    if len > max {
        return Err(CallError::TooLarge { what, len, max });
    }
    let mut bytes = Vec::new();
    stream.by_ref().take(u64::from(declared)).read_to_end(&mut bytes)?;
    if bytes.len() < len {
        return Err(CallError::Io(io::ErrorKind::UnexpectedEof.into()));
    }
    Ok(bytes)
}

/// A TCPROS connection header: `u32 total ‖ (u32 len ‖ "key=value")*`.
pub fn encode_header(fields: &[(&str, &str)]) -> Vec<u8> {
    let mut body = Vec::new();
    for (key, value) in fields {
        let field = format!("{key}={value}");
        body.extend_from_slice(&(field.len() as u32).to_le_bytes());
        body.extend_from_slice(field.as_bytes());
    }
    let mut bytes = (body.len() as u32).to_le_bytes().to_vec();
    bytes.extend_from_slice(&body);
    bytes
}

/// The fields of a connection header's body.
pub fn decode_header(body: &[u8]) -> Result<Vec<(String, String)>, CallError> {
    let mut fields = Vec::new();
    let mut rest = body;
    while !rest.is_empty() {
        let Some((len, tail)) = rest.split_first_chunk::<4>() else {
            return Err(CallError::Header(format!("ends inside a field length ({} bytes left)", rest.len())));
        };
        let len = u32::from_le_bytes(*len) as usize;
        let Some(field) = tail.get(..len) else {
            return Err(CallError::Header(format!("field of {len} bytes, {} left", tail.len())));
        };
        let text = String::from_utf8_lossy(field);
        let Some((key, value)) = text.split_once('=') else {
            return Err(CallError::Header(format!("field {text:?} has no `=`")));
        };
        fields.push((key.to_string(), value.to_string()));
        rest = &tail[len..];
    }
    Ok(fields)
}

/// `rosrpc://host:port` → a socket address.
pub fn service_address(uri: &str) -> Result<SocketAddr, CallError> {
    let bad = || CallError::Address(uri.to_string());
    let host_port = uri.strip_prefix("rosrpc://").ok_or_else(bad)?.trim_end_matches('/');
    host_port.to_socket_addrs().map_err(|_| bad())?.next().ok_or_else(bad)
}

/// What a call needs besides the request.
#[derive(Clone, Debug)]
pub struct CallTarget<'a> {
    pub address: SocketAddr,
    pub service: &'a str,
    pub caller_id: &'a str,
    pub timeout: Duration,
    /// Largest reply accepted, bytes.
    pub max_reply: usize,
}

/// Calls the Deliver service at `target` with `request`; the peer's answer or why there is none,
/// within `target.timeout`.
pub fn deliver(target: &CallTarget, request: &sgm_msgs::DeliverReq) -> Result<sgm_msgs::DeliverRes, CallError> {
    let deadline = Deadline { end: Instant::now() + target.timeout, total: target.timeout };
    let stream =
        TcpStream::connect_timeout(&target.address, deadline.left()?).map_err(|e| CallError::io(e, target.timeout))?;
    stream.set_nodelay(true)?;
    let mut stream = Bounded { stream, deadline: &deadline };

    let md5sum = sgm_msgs::Deliver::md5sum();
    let kind = sgm_msgs::Deliver::msg_type();
    let header = encode_header(&[
        ("callerid", target.caller_id),
        ("service", target.service),
        ("md5sum", &md5sum),
        ("type", &kind),
    ]);
    let mut body = Vec::new();
    request.encode(&mut body)?;
    let mut bytes = header;
    bytes.extend_from_slice(&(body.len() as u32).to_le_bytes());
    bytes.extend_from_slice(&body);
    stream.write_all(&bytes)?;

    read_reply(&mut stream, target.max_reply).map_err(|e| match e {
        CallError::Io(e) => CallError::io(e, target.timeout),
        e => e,
    })
}

/// What the peer sends back, read off `stream`: its connection header (refused if it names an
/// error), then `u8 ok ‖ u32 length ‖ reply`, a reply of at most `max_reply` bytes. Everything a
/// hostile peer controls is here (the `tcpros_reply` fuzz target feeds it bytes).
pub fn read_reply(stream: &mut impl Read, max_reply: usize) -> Result<sgm_msgs::DeliverRes, CallError> {
    let fields = decode_header(&read_counted(stream, "connection header", MAX_HEADER_BYTES)?)?;
    if let Some((_, error)) = fields.iter().find(|(k, _)| k == "error") {
        return Err(CallError::Refused(error.clone()));
    }
    let mut ok = [0u8; 1];
    stream.read_exact(&mut ok)?;
    let reply = read_counted(stream, "reply", max_reply)?;
    if ok[0] == 0 {
        // A failed call's reply is the bare error string.
        return Err(CallError::Refused(String::from_utf8_lossy(&reply).into_owned()));
    }
    // The reply's own length prefix came first: the message is the bytes after it.
    let res = sgm_msgs::DeliverRes::decode(&reply[..])?;
    Ok(res)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::TcpListener;
    use std::thread;

    fn request() -> sgm_msgs::DeliverReq {
        sgm_msgs::DeliverReq { from_robot: 4, data: vec![1, 2, 3] }
    }

    fn target(address: SocketAddr, timeout: Duration) -> CallTarget<'static> {
        CallTarget { address, service: "/sgm/robot_2/deliver", caller_id: "/sgm_alpha", timeout, max_reply: 1024 }
    }

    /// A one-connection server: reads what the client sends (header and request), then runs
    /// `answer` on the stream. Returns the address and what it read.
    fn server(answer: impl FnOnce(&mut TcpStream) + Send + 'static) -> (SocketAddr, thread::JoinHandle<Vec<u8>>) {
        let listener = TcpListener::bind("127.0.0.1:0").expect("a port");
        let address = listener.local_addr().expect("an address");
        let handle = thread::spawn(move || {
            let (mut stream, _) = listener.accept().expect("a client");
            let mut read = Vec::new();
            let mut chunk = [0u8; 4096];
            // Header, then the request: both length-prefixed.
            for _ in 0..2 {
                let mut len = [0u8; 4];
                stream.read_exact(&mut len).expect("a length");
                let mut body = vec![0u8; u32::from_le_bytes(len) as usize];
                stream.read_exact(&mut body).expect("a body");
                read.extend_from_slice(&len);
                read.extend_from_slice(&body);
            }
            answer(&mut stream);
            // Hold the connection until the client gives up.
            while stream.read(&mut chunk).is_ok_and(|n| n > 0) {}
            read
        });
        (address, handle)
    }

    fn reply_header() -> Vec<u8> {
        encode_header(&[("callerid", "/sgm_bravo"), ("md5sum", &sgm_msgs::Deliver::md5sum())])
    }

    #[test]
    fn a_call_writes_what_rosrust_reads_and_reads_what_it_writes() {
        let (address, server) = server(|s| {
            let res = sgm_msgs::DeliverRes { accepted: true, reason: "ok".into() };
            let mut body = Vec::new();
            res.encode(&mut body).expect("encodes");
            let mut bytes = reply_header();
            bytes.push(1);
            bytes.extend_from_slice(&(body.len() as u32).to_le_bytes());
            bytes.extend_from_slice(&body);
            s.write_all(&bytes).expect("writes");
        });
        let res = deliver(&target(address, Duration::from_secs(5)), &request()).expect("answered");
        assert_eq!(res, sgm_msgs::DeliverRes { accepted: true, reason: "ok".into() });
        let read = server.join().expect("server");
        // The header rosrust's service server matches on, then the request as rosrust encodes it.
        let header_len = u32::from_le_bytes(read[..4].try_into().expect("4 bytes")) as usize;
        let fields = decode_header(&read[4..4 + header_len]).expect("a header");
        let get = |k: &str| fields.iter().find(|(key, _)| key == k).map(|(_, v)| v.as_str());
        assert_eq!(get("service"), Some("/sgm/robot_2/deliver"));
        assert_eq!(get("md5sum"), Some(sgm_msgs::Deliver::md5sum().as_str()));
        assert_eq!(get("callerid"), Some("/sgm_alpha"));
        // encode_vec: rosrust's length prefix and the message, as its client sends them.
        let body = request().encode_vec().expect("encodes");
        assert_eq!(&read[4 + header_len..], &body[..]);
        let body = &body[4..];
        assert_eq!(&read[4 + header_len..8 + header_len], &(body.len() as u32).to_le_bytes());
        assert_eq!(&read[8 + header_len..], body);
    }

    #[test]
    fn a_peer_that_never_answers_costs_the_timeout_and_no_more() {
        let (address, _server) = server(|_| {});
        let timeout = Duration::from_millis(300);
        let started = Instant::now();
        let e = deliver(&target(address, timeout), &request()).expect_err("no answer");
        assert!(matches!(e, CallError::Timeout(t) if t == timeout), "{e}");
        // Bounded: the deadline covers the whole call (a generous margin, not a speed claim).
        assert!(started.elapsed() < Duration::from_secs(5));
    }

    #[test]
    fn nobody_listening_fails_at_once() {
        let address = TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).expect("a port");
        // The listener is gone: the port refuses.
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("refused");
        assert!(matches!(e, CallError::Io(ref io) if io.kind() == io::ErrorKind::ConnectionRefused), "{e}");
    }

    #[test]
    fn declared_lengths_beyond_the_bounds_are_refused_before_reading() {
        let (address, _server) = server(|s| {
            let mut bytes = reply_header();
            bytes.push(1);
            bytes.extend_from_slice(&u32::MAX.to_le_bytes());
            s.write_all(&bytes).expect("writes");
        });
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("refused");
        assert!(matches!(e, CallError::TooLarge { what: "reply", len, max: 1024 } if len == u32::MAX as usize), "{e}");
        let (address, _server) = server(|s| s.write_all(&u32::MAX.to_le_bytes()).expect("writes"));
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("refused");
        assert!(matches!(e, CallError::TooLarge { what: "connection header", .. }), "{e}");
    }

    #[test]
    fn refusals_and_early_ends_are_errors_with_the_reason() {
        let (address, _server) = server(|s| {
            s.write_all(&encode_header(&[("error", "md5sum mismatch")])).expect("writes");
        });
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("refused");
        assert_eq!(e.to_string(), "the service refused the call: md5sum mismatch");
        let (address, _server) = server(|s| {
            let mut bytes = reply_header();
            bytes.push(0);
            bytes.extend_from_slice(&5u32.to_le_bytes());
            bytes.extend_from_slice(b"busy!");
            s.write_all(&bytes).expect("writes");
        });
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("refused");
        assert_eq!(e.to_string(), "the service refused the call: busy!");
        let (address, _server) = server(|s| {
            let mut bytes = reply_header();
            bytes.push(1);
            bytes.extend_from_slice(&10u32.to_le_bytes());
            bytes.extend_from_slice(b"short");
            s.write_all(&bytes).expect("writes");
            s.shutdown(std::net::Shutdown::Write).expect("shuts");
        });
        let e = deliver(&target(address, Duration::from_secs(5)), &request()).expect_err("ended early");
        assert!(matches!(e, CallError::Io(ref io) if io.kind() == io::ErrorKind::UnexpectedEof), "{e}");
    }

    #[test]
    fn headers_round_trip_and_malformed_ones_are_named() {
        let bytes = encode_header(&[("a", "1"), ("service", "/x=y")]);
        let fields = decode_header(&bytes[4..]).expect("decodes");
        assert_eq!(fields, vec![("a".into(), "1".into()), ("service".into(), "/x=y".into())]);
        assert!(decode_header(&[1, 0]).unwrap_err().to_string().contains("field length"));
        assert!(decode_header(&[9, 0, 0, 0, b'a']).unwrap_err().to_string().contains("9 bytes, 1 left"));
        assert!(decode_header(&[1, 0, 0, 0, b'a']).unwrap_err().to_string().contains("no `=`"));
        assert_eq!(service_address("rosrpc://127.0.0.1:4000").expect("parses").port(), 4000);
        assert!(service_address("http://127.0.0.1:4000").is_err());
    }
}
