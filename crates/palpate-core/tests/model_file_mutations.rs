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
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
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
    for (what, v) in [
        ("a particle mass", m.particle_mass[0]),
        ("the wall volume", m.wall_volume),
        ("the core fraction", m.options.core_fraction),
    ] {
        let at = base.windows(8).position(|w| w == v.to_le_bytes()).unwrap_or_else(|| panic!("{what} in the file"));
        let mut b = base.clone();
        b[at..at + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let e = from_bytes(&refresh(b), "nan.palpate").err().unwrap_or_else(|| panic!("NaN {what} loaded"));
        assert!(e.to_string().contains("nan.palpate"), "{e}");
    }
}

/// The bytes of the corpus's model (python/tests/corpus_cases.py: the paper's ellipsoids, 400
/// particles, 8192 outer triangles), on which crafted ring counts made a load take 20-55 s.
fn ellipsoids_model() -> Vec<u8> {
    let wall = shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).expect("the ellipsoid wall");
    let o = HybridOptions { spacing: Spacing::Count(400), field_voxels: 20_000, ..Default::default() };
    to_bytes(&build(&wall, &o).expect("the ellipsoids model builds"))
}

/// `bytes` with every region's ring count (one byte per outer vertex, after its u64 length) set
/// to `rings`, checksum refreshed: a crafted file.
fn with_rings(bytes: &[u8], rings: u8) -> Vec<u8> {
    let m = from_bytes(bytes, "base").expect("loads");
    let mut section = (m.region_rings.len() as u64).to_le_bytes().to_vec();
    section.extend_from_slice(&m.region_rings);
    let at = bytes.windows(section.len()).position(|w| w == section.as_slice()).expect("the region rings in the file") + 8;
    let mut b = bytes.to_vec();
    b[at..at + m.region_rings.len()].fill(rings);
    refresh(b)
}

/// Load `bytes` as `HybridModel.load` does: (the model or None, seconds). A refusal must name the
/// file and the rings.
fn timed_load(bytes: &[u8]) -> (Option<palpate_core::hybrid::HybridModel>, f64) {
    let t = std::time::Instant::now();
    let r = from_bytes(bytes, "rings.palpate");
    let secs = t.elapsed().as_secs_f64();
    match r {
        Ok(m) => (Some(m), secs),
        Err(e) => {
            assert!(e.to_string().contains("rings.palpate") && e.to_string().contains("rings"), "{e}");
            (None, secs)
        }
    }
}

/// Seconds to regrow the first `n` regions (their triangles, curve and field), as the runtime
/// does for each region a tool activates.
fn regrow(m: &palpate_core::hybrid::HybridModel, n: usize) -> f64 {
    let t = std::time::Instant::now();
    for s in 0..n.min(m.n_regions()) {
        let _ = m.region_len(s);
        let _ = m.region_curve(s);
        let _ = m.region_field(s);
    }
    t.elapsed().as_secs_f64()
}

/// Issue 15's crafted files that took 20-55 s: every region ring count set to 255. Refused on
/// load, at once (the builder makes at most MAX_RINGS; the loader takes up to twice that); a
/// file at the largest count accepted loads at once, and a region of it costs about what one
/// the builder made costs to regrow (this model's regions all have MAX_RINGS rings already).
#[test]
fn crafted_ring_counts_are_refused_or_bounded() {
    let base = ellipsoids_model();
    let most = (2 * palpate_core::hybrid::options::MAX_RINGS) as u8;
    for rings in [255, most + 1] {
        let (m, secs) = timed_load(&with_rings(&base, rings));
        assert!(m.is_none(), "{rings} rings everywhere loaded");
        assert!(secs < 2.0, "{rings} rings everywhere: refusing took {secs:.1} s");
    }
    let (built, _) = timed_load(&base);
    let (crafted, secs) = timed_load(&with_rings(&base, most));
    let crafted = crafted.expect("the largest ring count accepted loads");
    assert!(secs < 2.0, "{most} rings everywhere: loading took {secs:.1} s");
    let (t_built, t_crafted) = (regrow(&built.expect("loads"), 20), regrow(&crafted, 20));
    assert!(t_crafted < 4.0 * t_built + 0.5, "{most} rings: 20 regions regrown in {t_crafted:.2} s, {t_built:.2} s as built");
}
