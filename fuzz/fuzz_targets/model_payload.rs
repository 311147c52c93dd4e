//! The input as a model file's payload, framed with a valid header and checksum: a crafted file
//! (the checksum stops only accidents), so the fuzzer reaches the section readers and the
//! semantic checks. A loaded model must then be usable: its info is computed and every region
//! regrown (what `palpate info` and the runtime do first).
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_core::hybrid::file::{checksum, from_bytes, FORMAT_VERSION, MAGIC};

fuzz_target!(|payload: &[u8]| {
    let mut bytes = Vec::with_capacity(40 + payload.len());
    bytes.extend_from_slice(MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    bytes.extend_from_slice(&checksum(payload).to_le_bytes());
    bytes.extend_from_slice(payload);
    if let Ok(m) = from_bytes(&bytes, "fuzz.palpate") {
        for s in 0..m.n_regions().min(64) {
            let _ = m.region_len(s);
            let _ = m.region_curve(s);
            let _ = m.region_field(s);
        }
    }
});
