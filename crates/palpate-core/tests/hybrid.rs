//! The hybrid model builder (paper §4, §6): volumes, particles, regions, skin, the transmural
//! field, and the model file.
//!
//! What a wrong implementation would do: a core that pokes out of the wall or a shell sampled
//! into the core double-counts volume (core + shell against the wall's volume); a region that
//! misses the particles under its triangles, a box that does not contain them, or a skin link
//! with barycentric coordinates outside the face breaks the activation and coupling the runtime
//! relies on; a transmural field solved with the wrong boundary values is not radial for
//! concentric spheres; a model file that is not written and read field by field is not
//! bit-identical after a round trip; a reader that trusts lengths and indices panics or hangs on
//! damaged or mutated files instead of naming the file and the reason.
use palpate_core::hybrid::file::{from_bytes, to_bytes, FORMAT_VERSION};
use palpate_core::hybrid::{build, HybridModel, HybridOptions, Projection, Spacing, VoxelLabel, Wall, WallPart};
use palpate_core::mesh::{ellipsoid_surface, TriSurface};
use palpate_core::spatial::{TetGrid, TriangleGrid};
use palpate_core::{HybridError, ModelFileError, Vec3};
#[path = "support/walls.rs"]
mod walls;

use walls::{ellipsoids, ventricle, INNER, OUTER};

fn check_volumes_and_particles(wall: &Wall, m: &HybridModel, what: &str) {
    let (core, shell) = (m.core_volume(), m.shell_volume());
    let rel = (core + shell) / m.wall_volume - 1.0;
    assert!(rel.abs() <= 0.02, "{what}: core {core:e} + shell {shell:e} vs wall {:e} m^3: {:.2}%", m.wall_volume, 100.0 * rel);
    let grid = TetGrid::new(&m.core_points, &m.core_tets, 2.0 * m.spacing);
    for (i, p) in m.particles.iter().enumerate() {
        assert!(wall.surface.contains_parity(p), "{what}: particle {i} at {p:?} is outside the wall");
        assert!(grid.locate(&m.core_points, p).is_none(), "{what}: particle {i} at {p:?} is inside the core");
    }
}

#[test]
fn ellipsoid_model_fills_the_wall_and_the_papers_layout_builds() {
    let (wall, m) = ellipsoids();
    // The automatic core of a closed wall: 300 coarse triangles x 3 (AUTO_CORE_TRIANGLES_CLOSED).
    assert!((800..=1400).contains(&m.core_tets.len()), "{} tets", m.core_tets.len());
    assert!((m.particles.len() as f64 / 28_000.0 - 1.0).abs() < 0.05, "{} particles", m.particles.len());
    assert!(m.core_quality.min_volume > 0.0);
    check_volumes_and_particles(wall, m, "ellipsoids");
    assert!(m.core_base_nodes.is_empty(), "a closed wall has no base");
    // Table 1's layout: 188 tets; ours with 64 coarse triangles x 3. Its core holds a smaller
    // share of the wall (the coarse chords cut into the cavity), which is why it is not the default.
    let paper = build(wall, &HybridOptions { core_triangles: 64, ..HybridOptions::default() }).unwrap();
    assert!((150..=250).contains(&paper.core_tets.len()), "{} tets", paper.core_tets.len());
    check_volumes_and_particles(wall, &paper, "ellipsoids, the paper's core");
    assert!(paper.core_volume() < 0.6 * m.core_volume(), "core {:e} vs {:e} m^3", paper.core_volume(), m.core_volume());
}

#[test]
fn truncated_ventricle_model_fills_the_wall_and_has_a_base() {
    let (wall, m) = ventricle();
    assert!((100..=1000).contains(&m.core_tets.len()), "{} tets", m.core_tets.len());
    assert!((m.particles.len() as f64 / 28_000.0 - 1.0).abs() < 0.05, "{} particles", m.particles.len());
    check_volumes_and_particles(wall, m, "ventricle");
    assert!(!m.core_base_nodes.is_empty());
    for &n in &m.core_base_nodes {
        assert!(m.core_points[n].z.abs() < 1e-3, "base node {n} at z = {}", m.core_points[n].z);
    }
}

fn check_regions_and_skin(m: &HybridModel, what: &str) {
    for s in 0..m.n_regions() {
        assert!(m.region_len(s) > 0, "{what}: region {s} has no particles");
        assert!(!m.region_core_faces(s).is_empty(), "{what}: region {s} has no core faces");
        assert!(m.region_curve(s).len() >= 3, "{what}: region {s}: C(p_s) has {} points", m.region_curve(s).len());
        let b = m.skin_bary[s];
        assert!(b.iter().all(|&x| (0.0..=1.0).contains(&x)) && (b.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{what}: skin {s}: {b:?}");
        let anchor = m.skin_anchor(s);
        assert!(((anchor + m.skin_offset[s]) - m.outer_points[s]).norm() < 1e-12);
    }
    // The gradient field of B(p_s) points inward at the boundary voxels: one voxel step along
    // it never moves away from the region's interior (distance measured to the nearest interior
    // voxel), on every region.
    let mut checked = 0;
    for s in 0..m.n_regions() {
        let f = m.region_field(s);
        let [nx, ny, _] = f.dims;
        let interior: Vec<[f64; 3]> = (0..f.label.len())
            .filter(|&v| f.label[v] == VoxelLabel::Inside)
            .map(|v| [(v % nx) as f64, ((v / nx) % ny) as f64, (v / (nx * ny)) as f64])
            .collect();
        let targets: Vec<[f64; 3]> = if interior.is_empty() {
            (0..f.label.len())
                .filter(|&v| f.label[v] == VoxelLabel::Boundary)
                .map(|v| [(v % nx) as f64, ((v / nx) % ny) as f64, (v / (nx * ny)) as f64])
                .collect()
        } else {
            interior
        };
        assert!(!targets.is_empty(), "{what}: region {s} has no inside voxel");
        let dist = |p: [f64; 3]| {
            targets
                .iter()
                .map(|t| ((t[0] - p[0]).powi(2) + (t[1] - p[1]).powi(2) + (t[2] - p[2]).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min)
        };
        for v in 0..f.label.len() {
            if f.label[v] != VoxelLabel::Boundary {
                continue;
            }
            let g = f.gradient[v];
            let p = [(v % nx) as f64, ((v / nx) % ny) as f64, (v / (nx * ny)) as f64];
            let d0 = dist(p);
            if d0 == 0.0 {
                continue; // a boundary voxel that is itself a target (no interior voxels)
            }
            assert!((g[0] * g[0] + g[1] * g[1] + g[2] * g[2] - 1.0).abs() < 1e-5, "{what}: region {s} voxel {v}: gradient {g:?}");
            let q = [p[0] + g[0] as f64, p[1] + g[1] as f64, p[2] + g[2] as f64];
            assert!(dist(q) < d0, "{what}: region {s} boundary voxel {v}: gradient {g:?} does not point inward");
            checked += 1;
        }
    }
    assert!(checked > 0);
}

#[test]
fn every_ellipsoid_region_and_skin_link_is_sound() {
    check_regions_and_skin(&ellipsoids().1, "ellipsoids");
}

#[test]
fn every_ventricle_region_and_skin_link_is_sound() {
    check_regions_and_skin(&ventricle().1, "ventricle");
}

#[test]
fn transmural_directions_are_radial_for_concentric_spheres() {
    let r = [0.02, 0.02, 0.02];
    let wall = Wall::nested(&ellipsoid_surface(r, 5), &ellipsoid_surface([0.03; 3], 5)).unwrap();
    let s = &wall.surface;
    let grid = TriangleGrid::new(s.points(), s.triangles(), 0.004);
    let f = palpate_core::hybrid::transmural::solve(s, &wall.parts, 0.0008, &grid);
    let mut worst: f64 = 0.0;
    for k in 0..200 {
        let dir = Vec3::new(((k * 37) % 17) as f64 - 8.0, ((k * 11) % 13) as f64 - 6.0, ((k * 7) % 11) as f64 - 5.0).normalize();
        let p = dir * 0.025;
        let d = f.dir_at(&p, Projection::Transmural);
        worst = worst.max(d.angle(&dir).to_degrees());
        // And phi is the harmonic solution (1/r_in - 1/r) / (1/r_in - 1/r_out), to the voxel size.
        let exact = (1.0 / 0.02 - 1.0 / 0.025) / (1.0 / 0.02 - 1.0 / 0.03);
        assert!((f.phi_at(&p) - exact).abs() < 0.05, "phi {} vs {exact}", f.phi_at(&p));
    }
    assert!(worst < 5.0, "largest angle to the radial direction {worst} deg");
}

#[test]
fn radial_mode_builds_for_a_star_shaped_wall() {
    let (wall, _) = ellipsoids();
    let o = HybridOptions { projection: Projection::Radial, ..Default::default() };
    let m = build(wall, &o).unwrap();
    check_volumes_and_particles(wall, &m, "ellipsoids, radial");
    assert!(m.stats.fallback_skin == 0 && m.stats.fallback_particle_outer == 0);
}

#[test]
fn save_then_load_is_bit_identical() {
    let m = &ellipsoids().1;
    let bytes = to_bytes(m);
    let back = from_bytes(&bytes, "mem").unwrap();
    assert!(back == *m, "loaded model differs");
    assert_eq!(to_bytes(&back), bytes);
    let dir = std::env::temp_dir().join(format!("palpate-hybrid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.palpate");
    m.save(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert!(HybridModel::load(&path).unwrap() == *m);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn damaged_model_files_give_clear_errors() {
    let bytes = to_bytes(&ventricle().1);
    let err = |b: &[u8]| from_bytes(b, "m.palpate").unwrap_err();
    // Foreign.
    assert!(matches!(err(b"solid cube\nfacet normal 0 0 1\n"), ModelFileError::NotAModel { .. }));
    assert!(matches!(err(&[]), ModelFileError::NotAModel { .. }));
    // Truncated, anywhere.
    for cut in [20, 39, 40, 41, bytes.len() / 2, bytes.len() - 1] {
        let e = err(&bytes[..cut]);
        assert!(matches!(e, ModelFileError::Truncated { .. }), "cut at {cut}: {e}");
        assert!(e.to_string().contains("m.palpate") && e.to_string().contains("truncated"), "{e}");
    }
    // Corrupted payload bytes.
    for at in [40, 1000, bytes.len() / 3, bytes.len() - 1] {
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        assert!(matches!(err(&b), ModelFileError::Checksum { .. }), "flip at {at}");
    }
    // Another version.
    let mut b = bytes.clone();
    b[16..20].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    let e = err(&b);
    assert!(matches!(e, ModelFileError::Version { found, .. } if found == FORMAT_VERSION + 1), "{e}");
    // Trailing garbage.
    let mut b = bytes.clone();
    b.extend_from_slice(b"xx");
    assert!(matches!(err(&b), ModelFileError::Corrupt { .. }));
}

#[test]
fn bad_walls_and_options_are_refused() {
    let inner = ellipsoid_surface(INNER, 3);
    let outer = ellipsoid_surface(OUTER, 3);
    // Swapped: the inner surface is not inside the outer one.
    assert!(matches!(Wall::nested(&outer, &inner), Err(HybridError::Surface(_))));
    // Off-centre inner surface poking through.
    let shifted: Vec<[f64; 3]> = inner.points().iter().map(|p| [p.x + 0.01, p.y, p.z]).collect();
    let tris: Vec<[i64; 3]> = inner.triangles().iter().map(|t| [t[0] as i64, t[1] as i64, t[2] as i64]).collect();
    let (moved, _) = TriSurface::from_arrays(&shifted, &tris).unwrap();
    let e = Wall::nested(&moved, &outer).unwrap_err();
    assert!(e.to_string().contains("outside the outer surface"), "{e}");
    // Tags.
    let wall = Wall::nested(&inner, &outer).unwrap();
    assert!(matches!(Wall::tagged(wall.surface.clone(), vec![WallPart::Outer; wall.surface.n_triangles()]), Err(HybridError::Parts(_))));
    assert!(matches!(Wall::tagged(wall.surface.clone(), vec![WallPart::Outer; 3]), Err(HybridError::Parts(_))));
    // Options.
    for o in [
        HybridOptions { core_fraction: 1.0, ..Default::default() },
        HybridOptions { core_fraction: f64::NAN, ..Default::default() },
        HybridOptions { core_triangles: 2, ..Default::default() },
        HybridOptions { core_layers: 17, ..Default::default() },
        HybridOptions { spacing: Spacing::Length(-1.0), ..Default::default() },
        HybridOptions { spacing: Spacing::Count(3), ..Default::default() },
        HybridOptions { density: 0.0, ..Default::default() },
    ] {
        assert!(matches!(build(&wall, &o), Err(HybridError::Parameter { .. })), "{o:?}");
    }
}

/// Damaged model files whose checksum was recomputed (so that the structure checks, not the
/// checksum, must catch them) never make the reader or the region accessors panic.
#[test]
fn mutated_model_files_never_panic() {
    use palpate_core::hybrid::file::checksum;
    let bytes = to_bytes(&ventricle().1);
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let (mut ok, mut refused) = (0, 0);
    for _ in 0..400 {
        let mut b = bytes.clone();
        // Mutate 1-4 bytes of the payload's first 64 KiB (counts, options, indices live there)
        // or anywhere.
        for _ in 0..1 + next() % 4 {
            let span = if next() % 2 == 0 { 65_536.min(b.len() - 40) } else { b.len() - 40 };
            let at = 40 + (next() as usize) % span;
            b[at] = next() as u8;
        }
        let sum = checksum(&b[40..]);
        b[32..40].copy_from_slice(&sum.to_le_bytes());
        match from_bytes(&b, "fuzz.palpate") {
            Ok(m) => {
                ok += 1;
                for s in [0, m.n_regions() / 2, m.n_regions() - 1] {
                    let _ = (m.region_len(s), m.region_core_faces(s), m.region_curve(s), m.region_field(s));
                }
            }
            Err(e) => {
                assert!(e.to_string().contains("fuzz.palpate"), "{e}");
                refused += 1;
            }
        }
    }
    assert!(ok > 0 && refused > 0, "ok {ok}, refused {refused}");
}

/// A file of another format version names the file and says to rebuild the model; a twisted
/// core is a typed error (the builder retries on it) whose message still says what to try.
#[test]
fn version_and_twisted_core_errors_say_what_to_do() {
    let mut b = to_bytes(&ellipsoids().1);
    b[16..20].copy_from_slice(&(FORMAT_VERSION + 7).to_le_bytes());
    let e = from_bytes(&b, "old.palpate").unwrap_err().to_string();
    assert!(e.contains("old.palpate") && e.contains("rebuild the model"), "{e}");
    let twisted = HybridError::TwistedCore { prism: 7, triangle: 3, radial: true }.to_string();
    assert!(
        twisted.starts_with("FEM core: prism 7 (coarse inner triangle 3) stays twisted")
            && twisted.contains("try more core triangles")
            && twisted.contains("use the transmural projection"),
        "{twisted}"
    );
    assert!(!HybridError::TwistedCore { prism: 7, triangle: 3, radial: false }.to_string().contains("radial"));
}
