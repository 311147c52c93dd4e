//! The UDP ends of the bridge (see `PROTOCOL.md`).
//!
//! The servo reads the socket non-blocking: each tick drains what arrived, answers hellos, keeps
//! the newest valid state packet of the open session and counts the others by reason; sending a
//! force is one non-blocking `send_to`. No allocation per tick (fixed buffers), no lock: the
//! session's id and address, and the last accepted sequence number, are atomics shared with the
//! sink (which the watchdog uses too).
//!
//! # Who may move the tool
//! Only the client the loop welcomed: a hello opens a session with a random 64-bit id drawn by
//! the loop; a state packet moves the tool only if it names that id, comes from the address and
//! port the hello came from, is newer than the session's last one, and (with a key) carries a
//! valid HMAC. A hello from another address is refused as `busy` while the session's client is
//! still sending (heard within [`BridgeOptions::handover`]); once it has been silent that long
//! the next hello takes the tool (a client that restarted on a new port waits that long; one on
//! the same port is welcomed at once). A bridge bound beyond the loopback interface refuses to
//! start without a key ([`BridgeError::KeyRequired`]): without one, anyone on the network who
//! saw a packet could forge the next.

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use palpate_core::Vec3;

use super::protocol::{self, Handshake, Key, Refusal, Reject, FLAG_ZEROED, FORCE_BYTES, KIND_HELLO, KIND_REFUSED, KIND_STATE, KIND_WELCOME};
use crate::device::{Device, DeviceInput, DeviceKind, ForceSink};

/// Receive buffer: larger than any valid packet, so that a long one is seen as long.
const RECV_BYTES: usize = 2048;

/// Default hand-over time: a hello from another client is refused while the session's client
/// was heard this recently \[s\]. Long against a device's packet gaps (1 ms; a dropped burst of
/// 100 ms is still a live client), short against a person restarting a device process.
pub const HANDOVER: Duration = Duration::from_millis(500);

/// How a bridge is opened.
#[derive(Debug, Clone)]
pub struct BridgeOptions {
    /// The shared key (None: unauthenticated, loopback only).
    pub key: Option<Key>,
    /// See [`HANDOVER`].
    pub handover: Duration,
}

impl Default for BridgeOptions {
    fn default() -> Self {
        BridgeOptions { key: None, handover: HANDOVER }
    }
}

/// Why a bridge could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("the bridge on {0} is reachable beyond this machine and needs a shared key (an HMAC on every packet, PROTOCOL.md); bind 127.0.0.1, or give a key")]
    KeyRequired(SocketAddrV4),
    #[error("cannot open the bridge on {0}: {1}")]
    Io(SocketAddrV4, std::io::Error),
}

/// The bridge's counters (read from any thread).
#[derive(Debug, Default)]
pub struct BridgeStats {
    pub received: AtomicU64,
    pub accepted: AtomicU64,
    rejected: [AtomicU64; Reject::ALL.len()],
    pub sent: AtomicU64,
    pub send_errors: AtomicU64,
    /// Hellos answered with a welcome (a repeated hello gets its session's again).
    pub welcomed: AtomicU64,
    /// Sessions opened (each a hello welcomed as a new session).
    pub sessions: AtomicU64,
    /// Who holds the tool: the session's address packed as in [`Peer`] (0: nobody yet).
    holder: AtomicU64,
    /// The last address a version-1 packet came from (packed, 0: none).
    old_client: AtomicU64,
}

impl BridgeStats {
    /// Packets dropped for `reason`.
    pub fn rejected(&self, reason: Reject) -> u64 {
        self.rejected[reason.index()].load(Ordering::Relaxed)
    }
    /// All dropped packets.
    pub fn dropped(&self) -> u64 {
        self.rejected.iter().map(|c| c.load(Ordering::Relaxed)).sum()
    }
    /// The address and port of the client holding the tool (the last session opened).
    pub fn holder(&self) -> Option<SocketAddrV4> {
        unpack(self.holder.load(Ordering::Acquire))
    }
    /// The last address that spoke protocol version 1 (refused: it has no sessions).
    pub fn old_client(&self) -> Option<SocketAddrV4> {
        unpack(self.old_client.load(Ordering::Acquire))
    }
    fn reject(&self, reason: Reject) {
        self.rejected[reason.index()].fetch_add(1, Ordering::Relaxed);
    }
}

const KNOWN: u64 = 1 << 48;

fn pack(a: SocketAddrV4) -> u64 {
    KNOWN | (u32::from(*a.ip()) as u64) << 16 | a.port() as u64
}
fn unpack(a: u64) -> Option<SocketAddrV4> {
    (a & KNOWN != 0).then(|| SocketAddrV4::new(Ipv4Addr::from(((a >> 16) & 0xffff_ffff) as u32), (a & 0xffff) as u16))
}

/// What the device and its sink share: the open session, for the forces.
struct Peer {
    /// The session's id (0: none, or being replaced).
    session: AtomicU64,
    /// The session client's address and port, packed.
    addr: AtomicU64,
    /// The last accepted state sequence number.
    ack: AtomicU32,
    /// The force packets' sequence number.
    seq: AtomicU32,
    stats: Arc<BridgeStats>,
}

impl Peer {
    /// The session's id and address, read consistently (None while there is none, or while
    /// [`Peer::open`] is replacing it).
    fn get(&self) -> Option<(u64, SocketAddrV4)> {
        let id = self.session.load(Ordering::Acquire);
        let addr = unpack(self.addr.load(Ordering::Acquire))?;
        (id != 0 && self.session.load(Ordering::Acquire) == id).then_some((id, addr))
    }
    fn open(&self, id: u64, addr: SocketAddrV4) {
        self.session.store(0, Ordering::Release);
        self.addr.store(pack(addr), Ordering::Release);
        self.ack.store(0, Ordering::Relaxed);
        self.session.store(id, Ordering::Release);
    }
}

/// The session the loop's side keeps.
#[derive(Debug, Clone, Copy)]
struct Session {
    id: u64,
    addr: SocketAddrV4,
    /// The hello's nonce (a repeated hello gets the same welcome).
    nonce: u64,
    last_seq: Option<u32>,
    /// When its client was last heard (its hello or its last accepted state).
    heard: Instant,
}

/// The loop's end: a [`Device`] fed by its session client's state packets.
pub struct Bridge {
    socket: UdpSocket,
    sink: Arc<BridgeSink>,
    session: Option<Session>,
    options: BridgeOptions,
    buf: [u8; RECV_BYTES],
    kind: DeviceKind,
}

impl Bridge {
    /// Binds `addr` without a key (e.g. `127.0.0.1:5005`; port 0 picks one, see
    /// [`Bridge::local_addr`]). `kind` chooses the coupling's and safety's defaults (the client's
    /// make, if known). Beyond loopback, see [`Bridge::open`].
    pub fn bind(addr: SocketAddrV4, kind: DeviceKind) -> Result<Bridge, BridgeError> {
        Bridge::open(addr, kind, BridgeOptions::default())
    }

    /// Binds `addr` with `options`; an address other than a loopback one needs a key.
    pub fn open(addr: SocketAddrV4, kind: DeviceKind, options: BridgeOptions) -> Result<Bridge, BridgeError> {
        if !addr.ip().is_loopback() && options.key.is_none() {
            return Err(BridgeError::KeyRequired(addr));
        }
        let io = |e| BridgeError::Io(addr, e);
        let socket = UdpSocket::bind(addr).map_err(io)?;
        socket.set_nonblocking(true).map_err(io)?;
        let out = socket.try_clone().map_err(io)?;
        let stats = Arc::new(BridgeStats::default());
        let peer = Peer { session: AtomicU64::new(0), addr: AtomicU64::new(0), ack: AtomicU32::new(0), seq: AtomicU32::new(0), stats };
        let sink = Arc::new(BridgeSink { socket: out, peer, key: options.key.clone() });
        Ok(Bridge { socket, sink, session: None, options, buf: [0; RECV_BYTES], kind })
    }

    /// On `127.0.0.1:port`.
    pub fn localhost(port: u16, kind: DeviceKind) -> Result<Bridge, BridgeError> {
        Bridge::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, port), kind)
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    pub fn stats(&self) -> Arc<BridgeStats> {
        self.sink.peer.stats.clone()
    }

    /// Drains the socket, answering hellos; the newest valid state of the session, if any
    /// arrived.
    pub fn poll(&mut self) -> Option<DeviceInput> {
        let mut newest = None;
        let stats = self.sink.peer.stats.clone();
        // Until WouldBlock (drained); other errors (an ICMP port-unreachable from a gone client on
        // some systems) end this tick's drain too: the loop holds the last state.
        while let Ok((n, from)) = self.socket.recv_from(&mut self.buf) {
            stats.received.fetch_add(1, Ordering::Relaxed);
            let SocketAddr::V4(from) = from else {
                continue; // bound to IPv4: cannot happen
            };
            let result = match protocol::kind_of(&self.buf[..n]) {
                Ok(KIND_STATE) => self.state(n, from).map(|input| newest = Some(input)),
                Ok(KIND_HELLO) => self.hello(n, from),
                Ok(_) => Err(Reject::BadKind),
                Err(r) => Err(r),
            };
            if let Err(r) = result {
                stats.reject(r);
                if r == Reject::OldVersion {
                    stats.old_client.store(pack(from), Ordering::Release);
                }
            }
        }
        newest
    }

    fn state(&mut self, n: usize, from: SocketAddrV4) -> Result<DeviceInput, Reject> {
        let state = protocol::decode_state(&self.buf[..n], self.options.key.as_ref())?;
        let s = self.session.as_mut().filter(|s| s.id == state.session).ok_or(Reject::NoSession)?;
        if s.addr != from {
            return Err(Reject::WrongPeer);
        }
        if s.last_seq.is_some_and(|last| !protocol::is_after(state.seq, last)) {
            return Err(Reject::OutOfOrder);
        }
        s.last_seq = Some(state.seq);
        s.heard = Instant::now();
        self.sink.peer.ack.store(state.seq, Ordering::Relaxed);
        self.sink.peer.stats.accepted.fetch_add(1, Ordering::Relaxed);
        Ok(state.input)
    }

    fn hello(&mut self, n: usize, from: SocketAddrV4) -> Result<(), Reject> {
        let key = self.options.key.as_ref();
        let nonce = match protocol::decode_handshake(&self.buf[..n], key) {
            Ok(Handshake::Hello { nonce }) => nonce,
            Ok(_) => return Err(Reject::BadKind),
            Err(Reject::BadTag) => {
                // Said unsigned (the refusal is advice; it opens nothing): a client with a wrong
                // key is told so, rather than timing out.
                let nonce = u64::from_le_bytes(self.buf[16..24].try_into().unwrap());
                self.answer(&Handshake::Refused { nonce, reason: Ok(Refusal::BadKey) }, from);
                return Err(Reject::BadTag);
            }
            Err(e) => return Err(e),
        };
        let now = Instant::now();
        match self.session {
            // The same hello again (its welcome was lost): the same session.
            Some(s) if s.addr == from && s.nonce == nonce => {}
            Some(s) if s.addr != from && now.duration_since(s.heard) < self.options.handover => {
                self.answer(&Handshake::Refused { nonce, reason: Ok(Refusal::Busy) }, from);
                return Err(Reject::Busy);
            }
            _ => {
                let Some(id) = protocol::random_u64() else {
                    return Err(Reject::Busy); // no randomness: no session can be safe
                };
                self.session = Some(Session { id, addr: from, nonce, last_seq: None, heard: now });
                self.sink.peer.open(id, from);
                let stats = &self.sink.peer.stats;
                stats.sessions.fetch_add(1, Ordering::Relaxed);
                stats.holder.store(pack(from), Ordering::Release);
            }
        }
        let id = self.session.map_or(0, |s| s.id);
        self.sink.peer.stats.welcomed.fetch_add(1, Ordering::Relaxed);
        self.answer(&Handshake::Welcome { session: id, nonce }, from);
        Ok(())
    }

    fn answer(&self, h: &Handshake, to: SocketAddrV4) {
        // A refusal is never signed (see protocol::decode_handshake).
        let key = if matches!(h, Handshake::Refused { .. }) { None } else { self.options.key.as_ref() };
        let b = protocol::encode_handshake(h, key);
        let stats = &self.sink.peer.stats;
        match self.socket.send_to(&b, to) {
            Ok(_) => stats.sent.fetch_add(1, Ordering::Relaxed),
            Err(_) => stats.send_errors.fetch_add(1, Ordering::Relaxed),
        };
    }
}

/// The bridge's force sink: one datagram per force to the session's client.
pub struct BridgeSink {
    socket: UdpSocket,
    peer: Peer,
    key: Option<Key>,
}

impl BridgeSink {
    fn send_flags(&self, force: &Vec3, flags: u32) {
        let Some((session, to)) = self.peer.get() else {
            return; // no client yet
        };
        let seq = self.peer.seq.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        let b = protocol::encode_force(session, seq, self.peer.ack.load(Ordering::Relaxed), force, flags, self.key.as_ref());
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

/// Why a client has no session.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("the loop at {0} refused the session: {1}")]
    Refused(SocketAddr, &'static str),
    #[error("no answer from the loop at {0} within {1:?}: is `palpate haptic --device bridge:PORT` running there, and does it speak protocol version {v}?", v = protocol::VERSION)]
    NoAnswer(SocketAddr, Duration),
    #[error("the bridge client's socket: {0}")]
    Io(#[from] std::io::Error),
}

/// The client's end: opens a session, sends states, receives forces.
pub struct Client {
    socket: UdpSocket,
    server: SocketAddr,
    key: Option<Key>,
    nonce: u64,
    session: u64,
    seq: u32,
}

impl Client {
    /// A client of the loop at `server` (unauthenticated), its session open: see
    /// [`Client::hello`] and [`Client::await_session`].
    pub fn connect(server: SocketAddr, timeout: Duration) -> Result<Client, ClientError> {
        let mut c = Client::hello(server, None)?;
        c.await_session(timeout)?;
        Ok(c)
    }

    /// Binds an ephemeral local port and sends a hello (with `key`'s tag if given); the session
    /// is open once [`Client::await_session`] returns (the loop must be polling meanwhile).
    pub fn hello(server: SocketAddr, key: Option<Key>) -> Result<Client, ClientError> {
        Client::hello_from(UdpSocket::bind(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 0))?, server, key)
    }

    /// [`Client::hello`] from a socket already bound (a client restarting on its old port).
    pub fn hello_from(socket: UdpSocket, server: SocketAddr, key: Option<Key>) -> Result<Client, ClientError> {
        socket.connect(server)?;
        let nonce = protocol::random_u64().unwrap_or(1);
        let c = Client { socket, server, key, nonce, session: 0, seq: 0 };
        c.send_hello()?;
        Ok(c)
    }

    fn send_hello(&self) -> std::io::Result<()> {
        // The loop may not be listening yet (ECONNREFUSED from an earlier send): try again.
        match self.socket.send(&protocol::encode_handshake(&Handshake::Hello { nonce: self.nonce }, self.key.as_ref())) {
            Err(e) if e.kind() != std::io::ErrorKind::ConnectionRefused => Err(e),
            _ => Ok(()),
        }
    }

    /// Waits for the loop's welcome, repeating the hello every 20 ms; a `busy` loop is asked
    /// again until `timeout`, a wrong key ends it at once. Returns the session id.
    pub fn await_session(&mut self, timeout: Duration) -> Result<u64, ClientError> {
        let t0 = Instant::now();
        let mut refused = None;
        let mut b = [0u8; RECV_BYTES];
        while t0.elapsed() < timeout {
            self.socket.set_read_timeout(Some(Duration::from_millis(20)))?;
            match self.socket.recv(&mut b) {
                Ok(n) => match protocol::decode_handshake(&b[..n], self.key.as_ref()) {
                    Ok(Handshake::Welcome { session, nonce }) if nonce == self.nonce => {
                        self.session = session;
                        self.seq = 0;
                        return Ok(session);
                    }
                    Ok(Handshake::Refused { nonce, reason: Ok(Refusal::BadKey) }) if nonce == self.nonce => {
                        return Err(ClientError::Refused(self.server, Refusal::BadKey.message()));
                    }
                    Ok(Handshake::Refused { nonce, reason }) if nonce == self.nonce => {
                        refused = Some(reason.map_or("an unknown reason", |r| r.message()));
                        continue;
                    }
                    _ => continue,
                },
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut | std::io::ErrorKind::ConnectionRefused) => {}
                Err(e) => return Err(e.into()),
            }
            self.send_hello()?;
        }
        Err(match refused {
            Some(why) => ClientError::Refused(self.server, why),
            None => ClientError::NoAnswer(self.server, timeout),
        })
    }

    /// The session's id (0 before the welcome).
    pub fn session(&self) -> u64 {
        self.session
    }

    /// This client's address and port.
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// The socket, to open another session from the same port.
    pub fn into_socket(self) -> UdpSocket {
        self.socket
    }

    /// Sends the next state packet; returns its sequence number.
    pub fn send(&mut self, input: &DeviceInput) -> std::io::Result<u32> {
        self.seq = self.seq.wrapping_add(1);
        self.socket.send(&protocol::encode_state(self.session, self.seq, input, self.key.as_ref()))?;
        Ok(self.seq)
    }
    /// Sends raw bytes (tests of malformed packets).
    pub fn send_raw(&self, b: &[u8]) -> std::io::Result<usize> {
        self.socket.send(b)
    }
    /// The next valid force packet of this session if one is waiting (never blocks).
    pub fn try_recv(&self) -> std::io::Result<Option<protocol::Force>> {
        // Non-blocking rather than a tiny timeout: Linux rounds a socket's timeout up to whole
        // scheduler ticks (1-4 ms), no shorter than the loop's period, so "drain what is
        // waiting" with a timeout may never end while forces keep coming.
        self.socket.set_nonblocking(true)?;
        let got = self.recv_valid();
        self.socket.set_nonblocking(false)?;
        got
    }
    /// The next valid force packet of this session, waiting at most `timeout` (`None` on
    /// timeout).
    pub fn recv(&self, timeout: Duration) -> std::io::Result<Option<protocol::Force>> {
        self.socket.set_read_timeout(Some(timeout))?;
        self.recv_valid()
    }
    fn recv_valid(&self) -> std::io::Result<Option<protocol::Force>> {
        let mut b = [0u8; FORCE_BYTES + 1];
        loop {
            match self.socket.recv(&mut b) {
                Ok(n) => {
                    if let Ok(f) = protocol::decode_force(&b[..n], self.key.as_ref()) {
                        if f.session == self.session {
                            return Ok(Some(f));
                        }
                    }
                }
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => return Ok(None),
                Err(e) => return Err(e),
            }
        }
    }
}

#[allow(dead_code)]
const _SIZES: () = assert!(protocol::STATE_BYTES < RECV_BYTES && KIND_WELCOME != KIND_REFUSED);
