//! The bridge's wire format, version 1 (`PROTOCOL.md` in this crate has the tables): encoding
//! and strict decoding of the state packet (client -> loop) and the force packet (loop ->
//! client). Decoding never panics and says why a packet was refused.

use palpate_core::Vec3;

use crate::device::DeviceInput;

/// `P L P H` as a little-endian u32.
pub const MAGIC: u32 = 0x4850_4C50;
pub const VERSION: u16 = 1;
pub const KIND_STATE: u16 = 1;
pub const KIND_FORCE: u16 = 2;
pub const STATE_BYTES: usize = 80;
pub const FORCE_BYTES: usize = 48;
/// Positions farther than this from the origin \[m\] are refused (a unit error).
pub const MAX_POSITION: f64 = 10.0;
/// Force flag: zeroed by a fault or the watchdog.
pub const FLAG_ZEROED: u32 = 1;

/// A decoded state packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State {
    pub seq: u32,
    pub input: DeviceInput,
}

/// A decoded force packet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Force {
    pub seq: u32,
    pub ack: u32,
    pub force: Vec3,
    pub flags: u32,
}

/// Why a packet was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    Short,
    Long,
    BadMagic,
    BadVersion,
    BadKind,
    NonFinite,
    OutOfRange,
    OutOfOrder,
}

impl Reject {
    pub const ALL: [Reject; 8] = [Reject::Short, Reject::Long, Reject::BadMagic, Reject::BadVersion, Reject::BadKind, Reject::NonFinite, Reject::OutOfRange, Reject::OutOfOrder];
    pub fn name(self) -> &'static str {
        match self {
            Reject::Short => "short",
            Reject::Long => "long",
            Reject::BadMagic => "bad_magic",
            Reject::BadVersion => "bad_version",
            Reject::BadKind => "bad_kind",
            Reject::NonFinite => "non_finite",
            Reject::OutOfRange => "out_of_range",
            Reject::OutOfOrder => "out_of_order",
        }
    }
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}
fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}
fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(b[at..at + 2].try_into().unwrap())
}

fn header(b: &[u8], size: usize, kind: u16) -> Result<u32, Reject> {
    if b.len() < size {
        return Err(Reject::Short);
    }
    if b.len() > size {
        return Err(Reject::Long);
    }
    if u32_at(b, 0) != MAGIC {
        return Err(Reject::BadMagic);
    }
    if u16_at(b, 4) != VERSION {
        return Err(Reject::BadVersion);
    }
    if u16_at(b, 6) != kind {
        return Err(Reject::BadKind);
    }
    Ok(u32_at(b, 8))
}

/// Encodes a state packet.
pub fn encode_state(seq: u32, input: &DeviceInput) -> [u8; STATE_BYTES] {
    let mut b = [0u8; STATE_BYTES];
    b[0..4].copy_from_slice(&MAGIC.to_le_bytes());
    b[4..6].copy_from_slice(&VERSION.to_le_bytes());
    b[6..8].copy_from_slice(&KIND_STATE.to_le_bytes());
    b[8..12].copy_from_slice(&seq.to_le_bytes());
    for i in 0..3 {
        b[16 + 8 * i..24 + 8 * i].copy_from_slice(&input.position[i].to_le_bytes());
    }
    for i in 0..4 {
        b[40 + 8 * i..48 + 8 * i].copy_from_slice(&input.orientation[i].to_le_bytes());
    }
    b[72..76].copy_from_slice(&input.buttons.to_le_bytes());
    b
}

/// Decodes a state packet (every check but the sequence order, which needs the last one).
pub fn decode_state(b: &[u8]) -> Result<State, Reject> {
    let seq = header(b, STATE_BYTES, KIND_STATE)?;
    let position = Vec3::new(f64_at(b, 16), f64_at(b, 24), f64_at(b, 32));
    let orientation = [f64_at(b, 40), f64_at(b, 48), f64_at(b, 56), f64_at(b, 64)];
    if !position.iter().chain(orientation.iter()).all(|c| c.is_finite()) {
        return Err(Reject::NonFinite);
    }
    let qn = orientation.iter().map(|c| c * c).sum::<f64>().sqrt();
    if position.norm() > MAX_POSITION || (qn - 1.0).abs() > 0.01 {
        return Err(Reject::OutOfRange);
    }
    Ok(State { seq, input: DeviceInput { position, orientation, buttons: u32_at(b, 72) } })
}

/// Is `seq` after `last` (serial-number arithmetic, RFC 1982)?
pub fn is_after(seq: u32, last: u32) -> bool {
    (seq.wrapping_sub(last) as i32) > 0
}

/// Encodes a force packet.
pub fn encode_force(seq: u32, ack: u32, force: &Vec3, flags: u32) -> [u8; FORCE_BYTES] {
    let mut b = [0u8; FORCE_BYTES];
    b[0..4].copy_from_slice(&MAGIC.to_le_bytes());
    b[4..6].copy_from_slice(&VERSION.to_le_bytes());
    b[6..8].copy_from_slice(&KIND_FORCE.to_le_bytes());
    b[8..12].copy_from_slice(&seq.to_le_bytes());
    b[12..16].copy_from_slice(&ack.to_le_bytes());
    for i in 0..3 {
        b[16 + 8 * i..24 + 8 * i].copy_from_slice(&force[i].to_le_bytes());
    }
    b[40..44].copy_from_slice(&flags.to_le_bytes());
    b
}

/// Decodes a force packet (the client's side).
pub fn decode_force(b: &[u8]) -> Result<Force, Reject> {
    let seq = header(b, FORCE_BYTES, KIND_FORCE)?;
    let force = Vec3::new(f64_at(b, 16), f64_at(b, 24), f64_at(b, 32));
    if !force.iter().all(|c| c.is_finite()) {
        return Err(Reject::NonFinite);
    }
    Ok(Force { seq, ack: u32_at(b, 12), force, flags: u32_at(b, 40) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_sequence_order() {
        let i = DeviceInput { position: Vec3::new(0.01, -0.02, 0.3), orientation: [1.0, 0.0, 0.0, 0.0], buttons: 3 };
        assert_eq!(decode_state(&encode_state(7, &i)), Ok(State { seq: 7, input: i }));
        let f = decode_force(&encode_force(9, 7, &Vec3::new(1.0, 2.0, -3.0), FLAG_ZEROED)).unwrap();
        assert_eq!((f.seq, f.ack, f.force, f.flags), (9, 7, Vec3::new(1.0, 2.0, -3.0), 1));
        assert!(is_after(1, 0) && is_after(0, u32::MAX) && !is_after(5, 5) && !is_after(4, 5));
    }
}
