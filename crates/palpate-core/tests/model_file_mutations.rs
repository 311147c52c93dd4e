//! Issue 15: the model-file loader under crafted input, in plain `cargo test` (the coverage-guided
//! targets of fuzz/ need nightly and cargo-fuzz). A small model's file is mutated thousands of
//! times (bytes replaced, words set to 0 / 1 / huge / NaN, truncated, and the checksum made right
//! again, as a crafted file would be): every load must return a model or a ModelFileError,
//! never panic, and a loaded model must answer the queries the runtime makes first. A wrong
//! loader that indexed without checking, or accepted a NaN mass, fails here.

use palpate_core::hybrid::file::{checksum, from_bytes, to_bytes};
use palpate_core::hybrid::{build, shapes, HybridOptions, Spacing};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;

const HEADER: usize = 40;

/// The bytes of a small model (a coarse ventricle, ~100 particles).
fn small_model() -> Vec<u8> {
    let p = TruncatedEllipsoidWall { circumferential: 8, longitudinal: 3, ..Default::default() };
    let wall = shapes::truncated_ventricle(&p).expect("the coarse ventricle wall");
    let o = HybridOptions { spacing: Spacing::Count(100), field_voxels: 1000, ..Default::default() };
    to_bytes(&build(&wall, &o).expect("the small model builds"))
}

/// `bytes` with the payload length and checksum made consistent again.
fn refresh(mut bytes: Vec<u8>) -> Vec<u8> {
    let payload_len = (bytes.len() - HEADER) as u64;
    let sum = checksum(&bytes[HEADER..]);
    bytes[24..32].copy_from_slice(&payload_len.to_le_bytes());
    bytes[32..40].copy_from_slice(&sum.to_le_bytes());
    bytes
}

/// A tiny deterministic generator (xorshift64*), so the test needs no dependency and repeats.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize { (self.next() % n as u64) as usize }
}

fn use_model(bytes: &[u8]) -> bool {
    match from_bytes(bytes, "mutant.palpate") {
        Ok(m) => {
            for s in 0..m.n_regions().min(8) {
                let _ = m.region_len(s);
                let _ = m.region_curve(s);
                let _ = m.region_field(s);
            }
            true
        }
        Err(e) => {
            assert!(e.to_string().contains("mutant.palpate"), "the error names the file: {e}");
            false
        }
    }
}

#[test]
fn crafted_model_files_load_or_fail_typed() {
    let base = small_model();
    assert!(use_model(&base), "the unmutated file loads");
    let mut rng = Rng(0x15_15_15_15);
    let words: [u64; 6] = [0, 1, u32::MAX as u64, 1 << 40, u64::MAX, f64::NAN.to_bits()];
    let (mut loaded, mut refused) = (0, 0);
    for k in 0..3000 {
        let mut b = base.clone();
        match k % 3 {
            0 => {
                for _ in 0..1 + rng.below(4) {
                    let i = HEADER + rng.below(b.len() - HEADER);
                    b[i] = rng.next() as u8;
                }
            }
            1 => {
                let i = HEADER + rng.below(b.len() - HEADER - 8);
                b[i..i + 8].copy_from_slice(&words[rng.below(words.len())].to_le_bytes());
            }
            _ => {
                let cut = HEADER + rng.below(b.len() - HEADER);
                b.truncate(cut);
            }
        }
        if use_model(&refresh(b)) {
            loaded += 1;
        } else {
            refused += 1;
        }
    }
    // Most mutations are refused; some hit a value that stays valid (a coordinate, an option).
    assert!(refused > 2000 && loaded > 0, "loaded {loaded}, refused {refused}");
}

#[test]
fn nan_fields_are_refused() {
    let base = small_model();
    let m = from_bytes(&base, "base").expect("loads");
    // Each of these values, found by its bytes in the file, replaced by NaN.
    for (what, v) in [("a particle mass", m.particle_mass[0]), ("the wall volume", m.wall_volume), ("the core fraction", m.options.core_fraction)] {
        let at = base.windows(8).position(|w| w == v.to_le_bytes()).unwrap_or_else(|| panic!("{what} in the file"));
        let mut b = base.clone();
        b[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let e = from_bytes(&refresh(b), "nan.palpate").err().unwrap_or_else(|| panic!("NaN {what} loaded"));
        assert!(e.to_string().contains("nan.palpate"), "{e}");
    }
}
