//! The input as a triangle surface's arrays (what every surface reader hands the core), then,
//! when valid, sampled with particles and used as a tagged wall: accept or refuse, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use palpate_core::mesh::{sample_inside, TriSurface};

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let n = (data[0] as usize % 24) + 3;
    let rest = &data[2..];
    let f = |i: usize| rest.get(8 * i..8 * i + 8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).unwrap_or(i as f64 * 0.37);
    let points: Vec<[f64; 3]> = (0..n).map(|i| [f(3 * i), f(3 * i + 1), f(3 * i + 2)]).collect();
    let idx = rest.get(24 * n..).unwrap_or(&[]);
    let tris: Vec<[i64; 3]> = idx.chunks_exact(3).map(|c| std::array::from_fn(|k| (c[k] % (n as u8 + 1)) as i64)).collect();
    if let Ok((s, _)) = TriSurface::from_arrays(&points, &tris) {
        let (lo, hi) = s.bounding_box();
        let extent = (hi - lo).norm();
        // A spacing from the input's last byte, at least extent/64: sampling stays small.
        let spacing = extent / (4.0 + (data[1] % 60) as f64);
        let _ = sample_inside(&s, spacing, 1000.0);
    }
});
