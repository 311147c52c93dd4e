//! The bridge's wire format, version 2 (`PROTOCOL.md` in this crate has the tables): encoding
//! and strict decoding of the handshake (hello, welcome, refused), the state packet (client ->
//! loop) and the force packet (loop -> client), each ending in an HMAC-SHA256 tag when the two
//! ends share a key. Decoding never panics and says why a packet was refused.
//!
//! Why sessions (version 1 had none): the loop took the first address that spoke, and a packet
//! from any other local port with a sequence number far ahead took the tool over. Now the tool
//! moves only for packets that carry the session id the loop drew at random for the client it
//! welcomed, from that client's address and port, and (with a key) signed with the key.

use hmac::{Hmac, Mac};
use palpate_core::Vec3;
use sha2::Sha256;

use crate::device::DeviceInput;

/// `P L P H` as a little-endian u32.
pub const MAGIC: u32 = 0x4850_4C50;
/// This protocol's version; any other is refused ([`Reject::BadVersion`], [`Reject::OldVersion`]).
pub const VERSION: u16 = 2;
pub const KIND_STATE: u16 = 1;
pub const KIND_FORCE: u16 = 2;
pub const KIND_HELLO: u16 = 3;
pub const KIND_WELCOME: u16 = 4;
pub const KIND_REFUSED: u16 = 5;
/// The HMAC-SHA256 tag at the end of every packet (zeros without a key).
pub const TAG_BYTES: usize = 32;
/// The common header: magic, version, kind, session id.
pub const HEADER_BYTES: usize = 16;
pub const STATE_BYTES: usize = 112;
pub const FORCE_BYTES: usize = 88;
/// Hello, welcome and refused.
pub const HANDSHAKE_BYTES: usize = 64;
/// The smallest key the loop takes \[bytes\] (128 bits).
pub const MIN_KEY_BYTES: usize = 16;
/// Positions farther than this from the origin \[m\] are refused (a unit error).
pub const MAX_POSITION: f64 = 10.0;
/// Force flag: zeroed by a fault or the watchdog.
pub const FLAG_ZEROED: u32 = 1;

/// Why the loop refused a hello (the `reason` of a refused packet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Another client holds the tool and is still sending.
    Busy = 1,
    /// The hello's tag does not verify with the loop's key (a wrong key, or none).
    BadKey = 2,
}

impl Refusal {
    pub fn from_code(c: u32) -> Option<Refusal> {
        match c {
            1 => Some(Refusal::Busy),
            2 => Some(Refusal::BadKey),
            _ => None,
        }
    }
    /// What a client should tell its user.
    pub fn message(self) -> &'static str {
        match self {
            Refusal::Busy => "another client holds the tool (the loop hands it over once that client has been silent for the hand-over time)",
            Refusal::BadKey => "the loop requires a shared key and this client's does not match",
        }
    }
}

/// The shared key of an authenticated bridge: HMAC-SHA256 over every packet's bytes before its
/// tag. The keyed state is made once and cloned per packet (no allocation).
#[derive(Clone)]
pub struct Key {
    mac: Hmac<Sha256>,
}

impl std::fmt::Debug for Key {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Key(..)") // never the key's bytes
    }
}

/// A key shorter than [`MIN_KEY_BYTES`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a bridge key needs at least {MIN_KEY_BYTES} bytes, got {0}")]
pub struct ShortKey(pub usize);

impl Key {
    pub fn new(bytes: &[u8]) -> Result<Key, ShortKey> {
        if bytes.len() < MIN_KEY_BYTES {
            return Err(ShortKey(bytes.len()));
        }
        // HMAC takes any key length: this cannot fail.
        let mac = <Hmac<Sha256> as Mac>::new_from_slice(bytes).map_err(|_| ShortKey(bytes.len()))?;
        Ok(Key { mac })
    }
    fn tag(&self, body: &[u8]) -> [u8; TAG_BYTES] {
        let mut m = self.mac.clone();
        m.update(body);
        m.finalize().into_bytes().into()
    }
    /// Does the packet's tag verify (constant time)?
    fn verifies(&self, packet: &[u8]) -> bool {
        let (body, tag) = packet.split_at(packet.len() - TAG_BYTES);
        let mut m = self.mac.clone();
        m.update(body);
        m.verify_slice(tag).is_ok()
    }
}

/// A decoded state packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State {
    pub session: u64,
    pub seq: u32,
    pub input: DeviceInput,
}

/// A decoded force packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Force {
    pub session: u64,
    pub seq: u32,
    pub ack: u32,
    pub force: Vec3,
    pub flags: u32,
}

/// A decoded handshake packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Handshake {
    /// Client -> loop: asks for a session; `nonce` is the client's, echoed in the answer.
    Hello { nonce: u64 },
    /// Loop -> client: the session the client must name in its state packets.
    Welcome { session: u64, nonce: u64 },
    /// Loop -> client: no session, and why (the code if unknown to this version).
    Refused { nonce: u64, reason: Result<Refusal, u32> },
}

/// Why a packet was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    Short,
    Long,
    BadMagic,
    BadVersion,
    /// A version-1 packet: a client older than sessions (the loop says so once, by name).
    OldVersion,
    BadKind,
    NonFinite,
    OutOfRange,
    OutOfOrder,
    /// The tag does not verify with the loop's key.
    BadTag,
    /// A state packet naming no open session (none open, or another id: a guess, or a session
    /// that was replaced).
    NoSession,
    /// A state packet with the session's id from another address or port.
    WrongPeer,
    /// A hello while another client holds the tool.
    Busy,
}

impl Reject {
    pub const ALL: [Reject; 13] = [
        Reject::Short,
        Reject::Long,
        Reject::BadMagic,
        Reject::BadVersion,
        Reject::OldVersion,
        Reject::BadKind,
        Reject::NonFinite,
        Reject::OutOfRange,
        Reject::OutOfOrder,
        Reject::BadTag,
        Reject::NoSession,
        Reject::WrongPeer,
        Reject::Busy,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Reject::Short => "short",
            Reject::Long => "long",
            Reject::BadMagic => "bad_magic",
            Reject::BadVersion => "bad_version",
            Reject::OldVersion => "old_version",
            Reject::BadKind => "bad_kind",
            Reject::NonFinite => "non_finite",
            Reject::OutOfRange => "out_of_range",
            Reject::OutOfOrder => "out_of_order",
            Reject::BadTag => "bad_tag",
            Reject::NoSession => "no_session",
            Reject::WrongPeer => "wrong_peer",
            Reject::Busy => "busy",
        }
    }
    /// Its index in [`Reject::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(b[at..at + 2].try_into().unwrap())
}

/// The packet's kind after the magic and version checks (any length from 8 bytes).
pub fn kind_of(b: &[u8]) -> Result<u16, Reject> {
    if b.len() < 8 {
        return Err(Reject::Short);
    }
    if u32_at(b, 0) != MAGIC {
        return Err(Reject::BadMagic);
    }
    match u16_at(b, 4) {
        VERSION => Ok(u16_at(b, 6)),
        1 => Err(Reject::OldVersion),
        _ => Err(Reject::BadVersion),
    }
}

/// The checks every packet passes: exact size, magic, version, kind, then the tag (with a key).
/// Returns the session id.
fn header(b: &[u8], size: usize, kind: u16, key: Option<&Key>) -> Result<u64, Reject> {
    if b.len() < size {
        // A short packet may still be an old client's: say so rather than "short".
        return Err(match kind_of(b) {
            Err(Reject::OldVersion) => Reject::OldVersion,
            _ => Reject::Short,
        });
    }
    let k = kind_of(b)?;
    if b.len() > size {
        return Err(Reject::Long);
    }
    if k != kind {
        return Err(Reject::BadKind);
    }
    if let Some(key) = key {
        if !key.verifies(b) {
            return Err(Reject::BadTag);
        }
    }
    Ok(u64_at(b, 8))
}

fn put_header(b: &mut [u8], kind: u16, session: u64) {
    b[0..4].copy_from_slice(&MAGIC.to_le_bytes());
    b[4..6].copy_from_slice(&VERSION.to_le_bytes());
    b[6..8].copy_from_slice(&kind.to_le_bytes());
    b[8..16].copy_from_slice(&session.to_le_bytes());
}

fn seal(b: &mut [u8], key: Option<&Key>) {
    let n = b.len() - TAG_BYTES;
    let tag = key.map_or([0; TAG_BYTES], |k| k.tag(&b[..n]));
    b[n..].copy_from_slice(&tag);
}

/// Encodes a state packet of session `session`.
pub fn encode_state(session: u64, seq: u32, input: &DeviceInput, key: Option<&Key>) -> [u8; STATE_BYTES] {
    let mut b = [0u8; STATE_BYTES];
    put_header(&mut b, KIND_STATE, session);
    b[16..20].copy_from_slice(&seq.to_le_bytes());
    b[20..24].copy_from_slice(&input.buttons.to_le_bytes());
    for i in 0..3 {
        b[24 + 8 * i..32 + 8 * i].copy_from_slice(&input.position[i].to_le_bytes());
    }
    for i in 0..4 {
        b[48 + 8 * i..56 + 8 * i].copy_from_slice(&input.orientation[i].to_le_bytes());
    }
    seal(&mut b, key);
    b
}

/// Decodes a state packet: every check but the session, the peer and the sequence order, which
/// need the loop's state. With `key`, the tag is checked before any field is read.
pub fn decode_state(b: &[u8], key: Option<&Key>) -> Result<State, Reject> {
    let session = header(b, STATE_BYTES, KIND_STATE, key)?;
    let position = Vec3::new(f64_at(b, 24), f64_at(b, 32), f64_at(b, 40));
    let orientation = [f64_at(b, 48), f64_at(b, 56), f64_at(b, 64), f64_at(b, 72)];
    if !position.iter().chain(orientation.iter()).all(|c| c.is_finite()) {
        return Err(Reject::NonFinite);
    }
    let qn = orientation.iter().map(|c| c * c).sum::<f64>().sqrt();
    if position.norm() > MAX_POSITION || (qn - 1.0).abs() > 0.01 {
        return Err(Reject::OutOfRange);
    }
    Ok(State { session, seq: u32_at(b, 16), input: DeviceInput { position, orientation, buttons: u32_at(b, 20) } })
}

/// Is `seq` after `last` (serial-number arithmetic, RFC 1982)?
pub fn is_after(seq: u32, last: u32) -> bool {
    (seq.wrapping_sub(last) as i32) > 0
}

/// Encodes a force packet of session `session`.
pub fn encode_force(session: u64, seq: u32, ack: u32, force: &Vec3, flags: u32, key: Option<&Key>) -> [u8; FORCE_BYTES] {
    let mut b = [0u8; FORCE_BYTES];
    put_header(&mut b, KIND_FORCE, session);
    b[16..20].copy_from_slice(&seq.to_le_bytes());
    b[20..24].copy_from_slice(&ack.to_le_bytes());
    for i in 0..3 {
        b[24 + 8 * i..32 + 8 * i].copy_from_slice(&force[i].to_le_bytes());
    }
    b[48..52].copy_from_slice(&flags.to_le_bytes());
    seal(&mut b, key);
    b
}

/// Decodes a force packet (the client's side; the session is the client's to compare).
pub fn decode_force(b: &[u8], key: Option<&Key>) -> Result<Force, Reject> {
    let session = header(b, FORCE_BYTES, KIND_FORCE, key)?;
    let force = Vec3::new(f64_at(b, 24), f64_at(b, 32), f64_at(b, 40));
    if !force.iter().all(|c| c.is_finite()) {
        return Err(Reject::NonFinite);
    }
    Ok(Force { session, seq: u32_at(b, 16), ack: u32_at(b, 20), force, flags: u32_at(b, 48) })
}

/// Encodes a handshake packet.
pub fn encode_handshake(h: &Handshake, key: Option<&Key>) -> [u8; HANDSHAKE_BYTES] {
    let mut b = [0u8; HANDSHAKE_BYTES];
    let (kind, session, nonce, reason) = match *h {
        Handshake::Hello { nonce } => (KIND_HELLO, 0, nonce, 0),
        Handshake::Welcome { session, nonce } => (KIND_WELCOME, session, nonce, 0),
        Handshake::Refused { nonce, reason } => (KIND_REFUSED, 0, nonce, reason.map_or_else(|c| c, |r| r as u32)),
    };
    put_header(&mut b, kind, session);
    b[16..24].copy_from_slice(&nonce.to_le_bytes());
    b[24..28].copy_from_slice(&reason.to_le_bytes());
    seal(&mut b, key);
    b
}

/// Decodes a handshake packet. A refusal is never signed (the loop may refuse a client for its
/// key), so its tag is not checked: a client treats it as advice, never as a session.
pub fn decode_handshake(b: &[u8], key: Option<&Key>) -> Result<Handshake, Reject> {
    let kind = match kind_of(b) {
        Ok(k) => k,
        Err(e) => return Err(if b.len() < 8 { Reject::Short } else { e }),
    };
    let key = if kind == KIND_REFUSED { None } else { key };
    let expect = match kind {
        KIND_HELLO | KIND_WELCOME | KIND_REFUSED => kind,
        _ => return Err(Reject::BadKind),
    };
    let session = header(b, HANDSHAKE_BYTES, expect, key)?;
    let nonce = u64_at(b, 16);
    Ok(match kind {
        KIND_HELLO => Handshake::Hello { nonce },
        KIND_WELCOME => Handshake::Welcome { session, nonce },
        _ => {
            let code = u32_at(b, 24);
            Handshake::Refused { nonce, reason: Refusal::from_code(code).ok_or(code) }
        }
    })
}

/// A random 64-bit value from the operating system (session ids, nonces): not guessable by
/// another process. `None` if the system's generator fails (then no session is opened).
pub fn random_u64() -> Option<u64> {
    let mut b = [0u8; 8];
    getrandom::getrandom(&mut b).ok()?;
    // Zero means "no session" on the wire.
    Some(u64::from_le_bytes(b)).filter(|&v| v != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input() -> DeviceInput {
        DeviceInput { position: Vec3::new(0.01, -0.02, 0.3), orientation: [1.0, 0.0, 0.0, 0.0], buttons: 3 }
    }

    #[test]
    fn round_trips_and_sequence_order() {
        let i = input();
        assert_eq!(decode_state(&encode_state(42, 7, &i, None), None), Ok(State { session: 42, seq: 7, input: i }));
        let f = decode_force(&encode_force(42, 9, 7, &Vec3::new(1.0, 2.0, -3.0), FLAG_ZEROED, None), None).unwrap();
        assert_eq!((f.session, f.seq, f.ack, f.force, f.flags), (42, 9, 7, Vec3::new(1.0, 2.0, -3.0), 1));
        assert!(is_after(1, 0) && is_after(0, u32::MAX) && !is_after(5, 5) && !is_after(4, 5));
        for h in [
            Handshake::Hello { nonce: 5 },
            Handshake::Welcome { session: 9, nonce: 5 },
            Handshake::Refused { nonce: 5, reason: Ok(Refusal::Busy) },
            Handshake::Refused { nonce: 5, reason: Err(77) },
        ] {
            assert_eq!(decode_handshake(&encode_handshake(&h, None), None), Ok(h));
        }
    }

    #[test]
    fn a_tag_verifies_only_with_its_key_and_its_bytes() {
        let k = Key::new(b"0123456789abcdef").unwrap();
        let other = Key::new(b"0123456789abcdeF").unwrap();
        let b = encode_state(42, 7, &input(), Some(&k));
        assert!(decode_state(&b, Some(&k)).is_ok());
        assert_eq!(decode_state(&b, Some(&other)), Err(Reject::BadTag));
        // Unsigned (a client without the key) against a keyed loop.
        assert_eq!(decode_state(&encode_state(42, 7, &input(), None), Some(&k)), Err(Reject::BadTag));
        // Every single bit flipped anywhere in the packet is caught, header and tag included.
        for byte in 0..STATE_BYTES {
            for bit in 0..8 {
                let mut t = b;
                t[byte] ^= 1 << bit;
                assert!(decode_state(&t, Some(&k)).is_err(), "byte {byte} bit {bit}");
            }
        }
        let h = encode_handshake(&Handshake::Hello { nonce: 1 }, Some(&k));
        assert_eq!(decode_handshake(&h, Some(&other)), Err(Reject::BadTag));
        assert!(Key::new(b"short").is_err());
        assert_eq!(format!("{k:?}"), "Key(..)");
    }

    #[test]
    fn a_version_one_packet_is_named_as_such() {
        let mut v1 = [0u8; 80];
        v1[0..4].copy_from_slice(&MAGIC.to_le_bytes());
        v1[4..6].copy_from_slice(&1u16.to_le_bytes());
        v1[6..8].copy_from_slice(&KIND_STATE.to_le_bytes());
        assert_eq!(decode_state(&v1, None), Err(Reject::OldVersion));
        assert_eq!(decode_handshake(&v1, None), Err(Reject::OldVersion));
        v1[4] = 3;
        assert_eq!(decode_state(&v1, None), Err(Reject::Short));
        assert!(Reject::ALL.iter().enumerate().all(|(i, r)| r.index() == i));
    }
}
