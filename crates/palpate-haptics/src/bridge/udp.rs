//! The UDP ends of the bridge (see `PROTOCOL.md`).
//!
//! The servo reads the socket non-blocking: each tick drains what arrived, keeps the newest
//! valid state packet and counts the others by reason; sending a force is one non-blocking
//! `send_to`. No allocation per tick (fixed buffers), no lock: the client's address and the
//! last accepted sequence number are atomics shared with the sink (which the watchdog uses).

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use palpate_core::Vec3;

use super::protocol::{self, Reject, FORCE_BYTES, FLAG_ZEROED, STATE_BYTES};
use crate::device::{Device, DeviceInput, DeviceKind, ForceSink};

/// Receive buffer: larger than any valid packet, so that a long one is seen as long.
const RECV_BYTES: usize = 2048;

/// The bridge's counters (read from any thread).
#[derive(Debug, Default)]
pub struct BridgeStats {
    pub received: AtomicU64,
    pub accepted: AtomicU64,
    rejected: [AtomicU64; 8],
    pub sent: AtomicU64,
    pub send_errors: AtomicU64,
}

impl BridgeStats {
    /// Packets dropped for `reason`.
    pub fn rejected(&self, reason: Reject) -> u64 {
        self.rejected[Reject::ALL.iter().position(|&r| r == reason).unwrap()].load(Ordering::Relaxed)
    }
    /// All dropped packets.
    pub fn dropped(&self) -> u64 {
        self.rejected.iter().map(|c| c.load(Ordering::Relaxed)).sum()
    }
    fn reject(&self, reason: Reject) {
        self.rejected[Reject::ALL.iter().position(|&r| r == reason).unwrap()].fetch_add(1, Ordering::Relaxed);
    }
}

/// What the device and its sink share.
struct Peer {
    /// The client's IPv4 address and port packed (`ip << 16 | port`), bit 48 set once known.
    addr: AtomicU64,
    /// The last accepted state sequence number.
    ack: AtomicU32,
    seq: AtomicU32,
    stats: Arc<BridgeStats>,
}

const KNOWN: u64 = 1 << 48;

impl Peer {
    fn get(&self) -> Option<SocketAddrV4> {
        let a = self.addr.load(Ordering::Acquire);
        (a & KNOWN != 0).then(|| SocketAddrV4::new(Ipv4Addr::from(((a >> 16) & 0xffff_ffff) as u32), (a & 0xffff) as u16))
    }
    fn set(&self, a: SocketAddrV4) {
        self.addr.store(KNOWN | (u32::from(*a.ip()) as u64) << 16 | a.port() as u64, Ordering::Release);
    }
}

/// The loop's end: a [`Device`] fed by a client's state packets.
pub struct Bridge {
    socket: UdpSocket,
    sink: Arc<BridgeSink>,
    last_seq: Option<u32>,
    buf: [u8; RECV_BYTES],
    kind: DeviceKind,
}

impl Bridge {
    /// Binds `addr` (e.g. `127.0.0.1:5005`; port 0 picks one, see [`Bridge::local_addr`]).
    /// `kind` chooses the coupling's and safety's defaults (the client's make, if known).
    pub fn bind(addr: SocketAddrV4, kind: DeviceKind) -> std::io::Result<Bridge> {
        let socket = UdpSocket::bind(addr)?;
        socket.set_nonblocking(true)?;
        let out = socket.try_clone()?;
        let stats = Arc::new(BridgeStats::default());
        let peer = Peer { addr: AtomicU64::new(0), ack: AtomicU32::new(0), seq: AtomicU32::new(0), stats: stats.clone() };
        Ok(Bridge { socket, sink: Arc::new(BridgeSink { socket: out, peer }), last_seq: None, buf: [0; RECV_BYTES], kind })
    }

    /// On `127.0.0.1:port`.
    pub fn localhost(port: u16, kind: DeviceKind) -> std::io::Result<Bridge> {
        Bridge::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, port), kind)
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    pub fn stats(&self) -> Arc<BridgeStats> {
        self.sink.peer.stats.clone()
    }

    /// Drains the socket; the newest valid state, if any arrived.
    pub fn poll(&mut self) -> Option<DeviceInput> {
        let mut newest = None;
        let stats = &self.sink.peer.stats;
        // Until WouldBlock (drained); other errors (an ICMP port-unreachable from a gone client on
        // some systems) end this tick's drain too: the loop holds the last state.
        while let Ok((n, from)) = self.socket.recv_from(&mut self.buf) {
            stats.received.fetch_add(1, Ordering::Relaxed);
            let state = match protocol::decode_state(&self.buf[..n]) {
                Ok(s) => s,
                Err(r) => {
                    stats.reject(r);
                    continue;
                }
            };
            if self.last_seq.is_some_and(|last| !protocol::is_after(state.seq, last)) {
                stats.reject(Reject::OutOfOrder);
                continue;
            }
            let SocketAddr::V4(from) = from else {
                continue; // bound to IPv4: cannot happen
            };
            self.last_seq = Some(state.seq);
            self.sink.peer.ack.store(state.seq, Ordering::Relaxed);
            self.sink.peer.set(from);
            stats.accepted.fetch_add(1, Ordering::Relaxed);
            newest = Some(state.input);
        }
        newest
    }
}

/// The bridge's force sink: one datagram per force to the client's address.
pub struct BridgeSink {
    socket: UdpSocket,
    peer: Peer,
}

impl BridgeSink {
    fn send_flags(&self, force: &Vec3, flags: u32) {
        let Some(to) = self.peer.get() else {
            return; // no client yet
        };
        let seq = self.peer.seq.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        let b = protocol::encode_force(seq, self.peer.ack.load(Ordering::Relaxed), force, flags);
        match self.socket.send_to(&b, to) {
            Ok(_) => self.peer.stats.sent.fetch_add(1, Ordering::Relaxed),
            Err(_) => self.peer.stats.send_errors.fetch_add(1, Ordering::Relaxed),
        };
    }
}

impl ForceSink for BridgeSink {
    fn send(&self, force: &Vec3) {
        self.send_flags(force, 0)
    }
    fn zeroed(&self) {
        self.send_flags(&Vec3::zeros(), FLAG_ZEROED)
    }
}

impl Device for Bridge {
    fn read(&mut self, _tick: u64, _dt: f64) -> Option<DeviceInput> {
        self.poll()
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        self.kind
    }
}

/// The client's end: sends states, receives forces (blocking with a timeout).
pub struct Client {
    socket: UdpSocket,
    seq: u32,
}

impl Client {
    /// A client of the loop at `server`, from an ephemeral local port.
    pub fn connect(server: SocketAddr) -> std::io::Result<Client> {
        let socket = UdpSocket::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0))?;
        socket.connect(server)?;
        Ok(Client { socket, seq: 0 })
    }
    /// Sends the next state packet; returns its sequence number.
    pub fn send(&mut self, input: &DeviceInput) -> std::io::Result<u32> {
        self.seq = self.seq.wrapping_add(1);
        self.socket.send(&protocol::encode_state(self.seq, input))?;
        Ok(self.seq)
    }
    /// Sends raw bytes (tests of malformed packets).
    pub fn send_raw(&self, b: &[u8]) -> std::io::Result<usize> {
        self.socket.send(b)
    }
    /// The next valid force packet if one is waiting (never blocks).
    pub fn try_recv(&self) -> std::io::Result<Option<protocol::Force>> {
        // Non-blocking rather than a tiny timeout: Linux rounds a socket's timeout up to whole
        // scheduler ticks (1-4 ms), no shorter than the loop's period, so "drain what is
        // waiting" with a timeout may never end while forces keep coming.
        self.socket.set_nonblocking(true)?;
        let got = self.recv_valid();
        self.socket.set_nonblocking(false)?;
        got
    }
    /// The next valid force packet, waiting at most `timeout` (`None` on timeout).
    pub fn recv(&self, timeout: Duration) -> std::io::Result<Option<protocol::Force>> {
        self.socket.set_read_timeout(Some(timeout))?;
        self.recv_valid()
    }
    fn recv_valid(&self) -> std::io::Result<Option<protocol::Force>> {
        let mut b = [0u8; FORCE_BYTES + 1];
        loop {
            match self.socket.recv(&mut b) {
                Ok(n) => {
                    if let Ok(f) = protocol::decode_force(&b[..n]) {
                        return Ok(Some(f));
                    }
                }
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => return Ok(None),
                Err(e) => return Err(e),
            }
        }
    }
}

#[allow(dead_code)]
const _SIZES: () = assert!(STATE_BYTES < RECV_BYTES);
