//! The input as a datagram to the haptic bridge: every decoder (state, force, handshake), with
//! and without a key, refuses or decodes, never panics; what decodes re-encodes to the same bytes
//! (no field is read from anywhere but where PROTOCOL.md puts it), and a decoded state is finite,
//! in range and a unit quaternion, as the servo assumes.
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_haptics::bridge::protocol::{self, Key, TAG_BYTES};

fuzz_target!(|data: &[u8]| {
    let key = Key::new(b"fuzzing key, 32 bytes, fixed....").unwrap();
    let _ = protocol::kind_of(data);
    for k in [None, Some(&key)] {
        if let Ok(s) = protocol::decode_state(data, k) {
            assert!(s.input.position.iter().all(|c| c.is_finite()) && s.input.position.norm() <= protocol::MAX_POSITION);
            let q = s.input.orientation;
            assert!(((q.iter().map(|c| c * c).sum::<f64>()).sqrt() - 1.0).abs() <= 0.01);
            let again = protocol::encode_state(s.session, s.seq, &s.input, k);
            let n = data.len() - TAG_BYTES;
            assert_eq!(&again[..n], &data[..n]);
            if k.is_some() {
                assert_eq!(&again[..], data, "a keyed packet that verifies has the tag we make");
            }
        }
        if let Ok(f) = protocol::decode_force(data, k) {
            assert!(f.force.iter().all(|c| c.is_finite()));
            let again = protocol::encode_force(f.session, f.seq, f.ack, &f.force, f.flags, k);
            // Bytes 52..56 are reserved (not read).
            assert_eq!(&again[..52], &data[..52]);
        }
        if let Ok(h) = protocol::decode_handshake(data, k) {
            let again = protocol::encode_handshake(&h, k);
            // Read: the header, the session of a welcome, the nonce, the reason of a refusal (the
            // encoder writes 0 where nothing is read).
            let (from, to) = match h {
                protocol::Handshake::Hello { .. } => (16, 24),
                protocol::Handshake::Welcome { .. } => (8, 24),
                protocol::Handshake::Refused { .. } => (16, 28),
            };
            assert_eq!((&again[..8], &again[from..to]), (&data[..8], &data[from..to]));
        }
    }
});
