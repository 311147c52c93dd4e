//! The runtime's parts (paper §6, §6.1): the tool's penalty contact, local activation with
//! hysteresis, and the confinement wall, each on its own (the tick composes them).
//!
//! What a wrong implementation would do: a contact force that is not minus the gradient of its
//! potential (a sign or a factor of 2 off) injects energy; damping applied while separating
//! pulls the tissue towards the tool (sticky contact); a tool force not equal and opposite to
//! the points' breaks momentum; an active set built by concatenating the regions' ranges holds
//! overlapping particles twice and steps them twice; hysteresis off by one toggles particles a
//! tick early or late; entered/left lists computed from the regions rather than from the
//! triangles report particles still covered by another region as leaving; a confinement field
//! pointing away from the region, or a force that is not the gradient of its energy, lets
//! particles escape or pumps energy into them; anything that allocates per tick breaks the
//! haptic loop's timing.
use palpate_core::error::ModelError;
use palpate_core::hybrid::{build, shapes, HybridModel, HybridOptions, VoxelLabel};
use palpate_core::integrate::CorePotential;
use palpate_core::material::Material;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use palpate_core::meshfree::ParticleModelBuilder;
use palpate_core::runtime::{Activation, AreaTool, Confinement, CoreContact, Placement, Sim, SimOptions, Tool, ToolOptions};
use palpate_core::Vec3;
use std::collections::BTreeSet;
use std::sync::OnceLock;

#[path = "support/alloc.rs"]
mod alloc;
use alloc::allocations;

const OUTER: [f64; 3] = [0.026, 0.026, 0.042];

/// The synthetic truncated ventricle of tests/hybrid.rs (28,000 particles).
fn ventricle() -> &'static HybridModel {
    static M: OnceLock<HybridModel> = OnceLock::new();
    M.get_or_init(|| {
        let wall = shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap();
        build(&wall, &HybridOptions::default()).unwrap()
    })
}

/// A small deterministic generator in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    fn vec(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
}

// ------------------------------------------------------------------------------------------
// Tool
// ------------------------------------------------------------------------------------------

#[test]
fn contact_force_is_minus_the_gradient_of_the_penalty() {
    let tool = Tool { radius: 5e-3, stiffness: 300.0, damping: 0.0 };
    let c = Vec3::new(0.01, -0.02, 0.003);
    let mut rng = Lcg(7);
    let mut checked = 0;
    for _ in 0..200 {
        let x = c + 5.5e-3 * rng.vec();
        let Some(k) = tool.contact(&c, &Vec3::zeros(), &x, &Vec3::zeros()) else { continue };
        if k.depth < 1e-5 {
            continue;
        }
        let eps = 1e-8;
        for a in 0..3 {
            let mut e = Vec3::zeros();
            e[a] = eps;
            let fd = -(tool.potential(&c, &(x + e)) - tool.potential(&c, &(x - e))) / (2.0 * eps);
            assert!((fd - k.force[a]).abs() <= 1e-6 * k.force.norm() + 1e-9, "axis {a}: fd {fd} vs {}", k.force[a]);
        }
        assert!((k.energy - tool.potential(&c, &x)).abs() < 1e-15);
        checked += 1;
    }
    assert!(checked > 50, "{checked} points in contact");
}

/// The tool against the skin (at its ties) and the core's surface inside the core's step
/// (`runtime::CoreContact`, used while the shell is off): its forces on the core's nodes are
/// minus the central differences of its energy, through the skin ties' turning frames, on a
/// randomly deformed core, with the tool on the skin and pressed past it onto the core's
/// surface; and they sum to the force the tool receives the opposite of. A force spread by the
/// tie's weights alone (not its exact transpose) fails the differences.
#[test]
fn core_contact_forces_are_minus_the_gradient_of_its_energy() {
    let material = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
    let sim = Sim::new(ventricle().clone(), material, SimOptions::default()).unwrap();
    let mut rng = Lcg(11);
    let x: Vec<Vec3> = sim.core.mesh().points().iter().map(|p| p + 2e-4 * rng.vec()).collect();
    let r = sim.options.tool.radius;
    let v0 = sim.hybrid.outer_points.len() / 3;
    let a0 = sim.core_surface[sim.core_surface.len() / 2];
    let skin_point = sim.skin.position(v0, &x);
    let outward = Vec3::new(skin_point.x, skin_point.y, 0.0).normalize();
    let (mut skin_checked, mut core_checked) = (0, 0);
    let faces: Vec<usize> = (0..sim.hybrid.core_faces.len()).collect();
    // A core face's centroid and outward normal: the tool pressed into it from outside, and with
    // its centre 1 mm beneath it (the contact's sign keeps pushing the tool out).
    let [fa, fb, fc] = sim.hybrid.core_faces[sim.hybrid.core_faces.len() / 3];
    let centroid = (x[fa] + x[fb] + x[fc]) / 3.0;
    let nf = (x[fb] - x[fa]).cross(&(x[fc] - x[fa])).normalize();
    for centre in [
        skin_point + outward * (r - 1.5e-3),
        x[a0] + outward * (r - 1.0e-3),
        centroid + nf * (r - 1.0e-3),
        centroid - nf * 1.0e-3,
    ] {
        let reach: Vec<usize> = (0..sim.hybrid.outer_points.len()).filter(|&v| (sim.skin.position(v, &x) - centre).norm() < r + 5e-3).collect();
        // A lift as a shed shell leaves the skin (constant offsets: the gradient holds with them).
        let lift: Vec<Vec3> = (0..sim.hybrid.outer_points.len()).map(|v| if v % 3 == 0 { 3e-4 * rng.vec() } else { Vec3::zeros() }).collect();
        let contact = CoreContact {
            sim: &sim,
            centre,
            skin: &reach,
            core: &faces,
            lift: &lift,
            lift_scale: 0.7,
            beneath: CoreContact::centre_is_beneath(&sim, &x, &centre),
        };
        let mut f = vec![Vec3::zeros(); x.len()];
        let u = contact.energy_forces(&x, &mut f);
        let sum = contact.sum(&x);
        assert!(u > 0.0 && sum.skin_contacts + sum.core_contacts > 0, "the tool touches nothing");
        skin_checked += sum.skin_contacts;
        core_checked += sum.core_contacts;
        let total: Vec3 = f.iter().sum();
        assert!((total - sum.force).norm() <= 1e-12 * sum.force.norm(), "forces sum to {total:?}, the contact's to {:?}", sum.force);
        let fmax = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let eps = 1e-8;
        let mut xp = x.clone();
        for i in (0..x.len()).filter(|&i| f[i] != Vec3::zeros()) {
            for c in 0..3 {
                xp[i][c] = x[i][c] + eps;
                let up = contact.energy_forces(&xp, &mut vec![Vec3::zeros(); x.len()]);
                xp[i][c] = x[i][c] - eps;
                let um = contact.energy_forces(&xp, &mut vec![Vec3::zeros(); x.len()]);
                xp[i][c] = x[i][c];
                let fd = -(up - um) / (2.0 * eps);
                assert!((fd - f[i][c]).abs() <= 1e-5 * fmax, "node {i} axis {c}: -dU/dx {fd:e} vs force {:e}", f[i][c]);
            }
        }
    }
    println!("checked with {skin_checked} skin vertices and {core_checked} core surface contacts");
    assert!(core_checked >= 3, "the presses did not reach the core's surface");
    // Beneath a face the contact is deeper than the tool's radius and still pushes the tool out
    // (the tissue's force points inward): a sign taken from the distance alone would let it
    // through (measured: the tool passed the held core of the paper's ellipsoids, 7 mm in).
    let inside = centroid - nf * 1.0e-3;
    assert!(
        CoreContact::centre_is_beneath(&sim, &x, &inside) && !CoreContact::centre_is_beneath(&sim, &x, &(centroid + nf * 1.0e-3)),
        "the core's faces' winding tells no side"
    );
    let beneath = CoreContact { sim: &sim, centre: inside, skin: &[], core: &faces, lift: &[], lift_scale: 0.0, beneath: true };
    let s = beneath.sum(&x);
    assert!(s.core_contacts == 1 && (s.max_depth - (r + 1.0e-3)).abs() < 1e-9, "depth {} beneath the face", s.max_depth);
    assert!(s.force.dot(&nf) < -0.99 * s.force.norm(), "the force on the tissue {:?} does not push it in along {nf:?}", s.force);
}

/// The core's faces point out of the core (towards the shell), as the tool's contact with the
/// core's surface assumes for its side (`runtime::core_contact`): each face's normal points away
/// from the fourth node of the core tetrahedron it bounds.
#[test]
fn core_faces_point_out_of_the_core() {
    let m = ventricle();
    let x = &m.core_points;
    for (f, face) in m.core_faces.iter().enumerate() {
        let mut sorted = *face;
        sorted.sort_unstable();
        let tet = m
            .core_tets
            .iter()
            .find(|t| sorted.iter().all(|a| t.contains(a)))
            .unwrap_or_else(|| panic!("face {f} bounds no tetrahedron"));
        let fourth = *tet.iter().find(|a| !face.contains(a)).unwrap();
        let n = (x[face[1]] - x[face[0]]).cross(&(x[face[2]] - x[face[0]]));
        assert!(n.dot(&(x[fourth] - x[face[0]])) < 0.0, "face {f} points into the core");
    }
}

#[test]
fn no_contact_force_outside_the_sphere_or_on_bad_input() {
    let tool = Tool::default();
    let c = Vec3::new(0.0, 0.0, 0.0);
    let v = Vec3::new(-1.0, 0.0, 0.0);
    for r in [5.0e-3, 5.0001e-3, 6e-3, 1.0] {
        assert!(tool.contact(&c, &Vec3::zeros(), &Vec3::new(r, 0.0, 0.0), &v).is_none(), "r = {r}");
        assert_eq!(tool.potential(&c, &Vec3::new(r, 0.0, 0.0)), 0.0);
    }
    assert!(tool.contact(&c, &Vec3::zeros(), &c, &v).is_none(), "no normal at the centre");
    let nan = Vec3::new(f64::NAN, 0.0, 0.0);
    assert!(tool.contact(&c, &Vec3::zeros(), &nan, &v).is_none());
    assert!(tool.contact(&nan, &Vec3::zeros(), &Vec3::new(1e-3, 0.0, 0.0), &v).is_none());
    assert_eq!(tool.potential(&nan, &c), 0.0);
    // Just inside: a small force along +x.
    let k = tool.contact(&c, &Vec3::zeros(), &Vec3::new(4.9e-3, 0.0, 0.0), &Vec3::zeros()).unwrap();
    assert!((k.force - Vec3::new(tool.stiffness * 1e-4, 0.0, 0.0)).norm() < 1e-9);
}

#[test]
fn the_tool_receives_the_opposite_of_the_points_forces() {
    let tool = Tool::default();
    let c = Vec3::new(0.001, 0.002, -0.003);
    let tv = Vec3::new(0.01, -0.02, 0.0);
    let mut rng = Lcg(11);
    let x: Vec<Vec3> = (0..100).map(|_| c + 6e-3 * rng.vec()).collect();
    let v: Vec<Vec3> = (0..100).map(|_| 0.05 * rng.vec()).collect();
    let mut f = vec![Vec3::zeros(); 100];
    let which: Vec<usize> = (0..100).chain([100, usize::MAX]).collect(); // out of range skipped
    let sum = tool.apply(&c, &tv, &x, &v, &which, &mut f);
    let total: Vec3 = f.iter().sum();
    assert!(sum.count > 10);
    assert!((sum.force_on_tool + total).norm() <= 1e-15 * total.norm().max(1.0), "{:?} vs {:?}", sum.force_on_tool, total);
    assert!(sum.max_depth > 0.0 && sum.max_depth <= tool.radius);
}

#[test]
fn damping_resists_approach_and_never_pulls() {
    let tool = Tool { radius: 5e-3, stiffness: 60.0, damping: 10.0 }; // huge damping
    let c = Vec3::zeros();
    let x = Vec3::new(4e-3, 0.0, 0.0); // 1 mm deep, normal +x
    let spring = 60.0 * 1e-3;
    let fx = |v: Vec3, tv: Vec3| tool.contact(&c, &tv, &x, &v).unwrap().force;
    // Approaching (moving towards the centre): more than the spring, by c * speed.
    let f = fx(Vec3::new(-0.1, 0.0, 0.0), Vec3::zeros());
    assert!((f.x - (spring + 10.0 * 0.1)).abs() < 1e-12 && f.y == 0.0 && f.z == 0.0, "{f:?}");
    // The tool moving into a point at rest is an approach too.
    assert!((fx(Vec3::zeros(), Vec3::new(0.1, 0.0, 0.0)).x - (spring + 1.0)).abs() < 1e-12);
    // Separating fast: the spring alone (damping would make it negative: it must not pull).
    for speed in [1e-3, 0.1, 10.0] {
        let f = fx(Vec3::new(speed, 0.0, 0.0), Vec3::zeros());
        assert!(f.x >= 0.0 && (f.x - spring).abs() < 1e-12, "separating at {speed}: {f:?}");
    }
    // Tangential sliding: no damping along the normal, no tangential force.
    let f = fx(Vec3::new(0.0, 0.3, 0.0), Vec3::zeros());
    assert!((f - Vec3::new(spring, 0.0, 0.0)).norm() < 1e-12);
}

#[test]
fn stiffness_and_damping_helpers() {
    assert!((Tool::stiffness_for(2e-6, 5e-5) - 0.76 * 800.0).abs() < 1e-9);
    for (m, h) in [(0.0, 1e-5), (1e-6, 0.0), (-1.0, 1e-5), (f64::NAN, 1e-5), (1.0, f64::INFINITY), (1.0, 1e-300)] {
        assert_eq!(Tool::stiffness_for(m, h), 0.0, "m {m} h {h}");
    }
    assert!((Tool::damping_for(60.0, 7e-7, 0.5) - (60.0f64 * 7e-7).sqrt()).abs() < 1e-15);
    assert_eq!(Tool::damping_for(-1.0, 2e-6, 0.5), 0.0);
    // The default is ~10x the per-point tissue stiffness and within the stability limit of the
    // test model (see default_stiffness_against_the_test_model for the measurement).
    let t = Tool::default();
    assert_eq!((t.radius, t.stiffness), (5e-3, 60.0));
    assert_eq!(Confinement::default(), Confinement { stiffness: 60.0, reach: 3 });
}

/// The runtime's contact is per unit of skin area (tool.rs docs): the skin vertices' areas share
/// the skin's, the default is ten times the tissue's Hertz stiffness per unit area at a
/// quarter-radius press and follows the radius, a given one is kept, nonsense is refused by name.
#[test]
fn the_contact_is_per_unit_of_skin_area() {
    let m = ventricle();
    let mat = Material::myocardium();
    let sim = Sim::new(m.clone(), mat, SimOptions::default()).unwrap();
    let p = &m.outer_points;
    // A third of each triangle's area to each of its vertices (they sum to the skin's area), at
    // most the cap: this skin (2.7 mm^2 a vertex on a 0.9 mm lattice) is mostly capped.
    let mut third = vec![0.0; p.len()];
    for t in &m.outer_tris {
        let a = 0.5 * (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]])).norm() / 3.0;
        t.iter().for_each(|&v| third[v] += a);
    }
    let cap = palpate_core::runtime::sim::SKIN_AREA_CAP_SPACINGS2 * m.spacing * m.spacing;
    assert_eq!(sim.skin_area.len(), p.len());
    assert!(sim.skin_area.iter().zip(&third).all(|(&a, &t)| (a - t.min(cap)).abs() <= 1e-12 * t && a > 0.0));
    let capped = third.iter().filter(|&&t| t > cap).count();
    assert!(capped > 0 && capped < p.len(), "{capped} of {} capped", p.len());
    let e_star = mat.young() / (1.0 - mat.poisson().powi(2));
    let r = sim.tool.radius;
    assert_eq!(r, 5e-3);
    // Ten times the tissue's stiffness per unit area under the smallest contact the lattice
    // resolves (radius min(R / 2, 2 h)): on this 0.9 mm lattice the spacing sets it.
    let a_min = (0.5 * r).min(2.0 * m.spacing);
    assert!(2.0 * m.spacing < 0.5 * r);
    assert!(sim.tool.stiffness >= 10.0 * e_star / (1.7 * a_min), "{} N/m^3", sim.tool.stiffness);
    assert_eq!(sim.tool.stiffness, AreaTool::default_stiffness(&mat, r, m.spacing));
    let with = |tool: ToolOptions| Sim::new(m.clone(), mat, SimOptions { tool, ..SimOptions::default() });
    // A larger sphere keeps it; a smaller one than four spacings is stiffer, as 1 / R.
    let big = with(ToolOptions { radius: 2.0 * r, ..ToolOptions::default() }).unwrap();
    assert_eq!(big.tool.stiffness, sim.tool.stiffness);
    let small = with(ToolOptions { radius: 1e-3, ..ToolOptions::default() }).unwrap();
    assert!((small.tool.stiffness * 1e-3 / (12.0 * e_star) - 1.0).abs() < 1e-12);
    assert_eq!(with(ToolOptions { area_stiffness: Some(1e7), ..ToolOptions::default() }).unwrap().tool.stiffness, 1e7);
    for (tool, name) in [
        (ToolOptions { area_stiffness: Some(f64::NAN), ..ToolOptions::default() }, "tool_area_stiffness [N/m^3]"),
        (ToolOptions { area_stiffness: Some(-1.0), ..ToolOptions::default() }, "tool_area_stiffness [N/m^3]"),
        (ToolOptions { radius: 0.0, ..ToolOptions::default() }, "tool_radius [m]"),
        (ToolOptions { area_damping: f64::INFINITY, ..ToolOptions::default() }, "tool_area_damping [N s/m^3]"),
    ] {
        assert!(matches!(with(tool), Err(ModelError::Parameter { name: n, .. }) if n == name), "{tool:?}");
    }
}

/// The numbers behind DEFAULT_STIFFNESS (a point penalty's default; tool.rs docs): the model's particle mass, the stable
/// sub-step of a particle body on its lattice (spacing and masses of the model, myocardium, the
/// support radius of tests/meshfree.rs), the stability bound m / h^2 and the tissue's E* R.
#[test]
fn default_stiffness_against_the_test_model() {
    let m = ventricle();
    let mat = Material::myocardium();
    let m_min = m.particle_mass.iter().copied().fold(f64::INFINITY, f64::min);
    let m_mean = m.particle_mass.iter().sum::<f64>() / m.particle_mass.len() as f64;
    // A block of the model's lattice (some shell particles near the base are isolated, which a
    // particle body refuses: the runtime will have to handle them; the step is a local property).
    let n = 8;
    let pts: Vec<Vec3> = (0..n * n * n).map(|i| Vec3::new((i % n) as f64, ((i / n) % n) as f64, (i / (n * n)) as f64) * m.spacing).collect();
    let body = ParticleModelBuilder::new(pts, vec![m_mean; n * n * n], mat, 1.8 * m.spacing).build().unwrap();
    let h = body.stable_dt();
    let k_stable = Tool::stiffness_for(m_min, h);
    let e_star = mat.young() / (1.0 - mat.poisson().powi(2));
    let k_tissue = e_star * Tool::default().radius;
    let n_surface = std::f64::consts::PI * (5e-3 * 1.25e-3) / (m.spacing * m.spacing); // patch at 1.25 mm depth
    let k = Tool::default().stiffness;
    println!(
        "spacing {:.3e} m, mass min {m_min:.3e} mean {m_mean:.3e} kg, stable sub-step {h:.3e} s, stiffness_for = 0.76 m_min/h^2 = {k_stable:.0} N/m, E*R = {k_tissue:.0} N/m over ~{n_surface:.0} surface points = {:.1} N/m each; default {k} N/m: omega h = {:.2}",
        m.spacing,
        k_tissue / n_surface,
        (k / m_min).sqrt() * h
    );
    assert!(k <= k_stable, "default stiffness above the stability bound {k_stable} N/m");
    assert!(k >= 5.0 * k_tissue / n_surface, "default stiffness not well above the tissue's per point");
}

// ------------------------------------------------------------------------------------------
// Activation
// ------------------------------------------------------------------------------------------

fn naive_union(m: &HybridModel, regions: &[usize]) -> Vec<usize> {
    let set: BTreeSet<usize> = regions.iter().flat_map(|&s| m.region_particle_ranges(s)).flatten().collect();
    set.into_iter().collect()
}

#[test]
fn region_table_matches_the_model() {
    let m = ventricle();
    let a = Activation::new(m, 0);
    assert_eq!(a.n_regions(), m.n_regions());
    for s in (0..m.n_regions()).step_by(7) {
        assert_eq!(a.region_triangles(s), m.region_triangles(s).as_slice(), "region {s}");
    }
    assert!(a.region_triangles(m.n_regions()).is_empty());
    println!("region-triangle table: {} bytes for {} regions", a.table_bytes(), a.n_regions());
}

#[test]
fn union_of_overlapping_regions_has_no_duplicates() {
    let m = ventricle();
    let mut a = Activation::new(m, 0);
    // Two neighbouring vertices: their regions overlap.
    let s = m.outer_tris[m.outer_tris.len() / 2][0];
    let t = m.outer_tris[m.outer_tris.len() / 2][1];
    let (ra, rb) = (naive_union(m, &[s]), naive_union(m, &[t]));
    assert!(ra.iter().any(|p| rb.binary_search(p).is_ok()), "regions {s} and {t} do not overlap");
    a.touch(s);
    a.touch(t);
    a.touch(s); // twice: once
    assert!(!a.touch(usize::MAX) && !a.touch(m.n_regions()));
    let sets = a.update(0);
    let want = naive_union(m, &[s, t]);
    assert_eq!(sets.active, want.as_slice());
    assert_eq!(sets.entered, want.as_slice());
    assert!(sets.left.is_empty());
    assert!(want.len() < ra.len() + rb.len());
    assert!(sets.active.windows(2).all(|w| w[0] < w[1]));
}

#[test]
fn hysteresis_keeps_a_region_exactly_linger_ticks() {
    let m = ventricle();
    for linger in [0u64, 1, 5] {
        let mut a = Activation::new(m, linger);
        let s = 100;
        a.touch(s);
        let n = a.update(10).active.len();
        assert_eq!(n, m.region_len(s));
        for tick in 11..=10 + linger {
            let sets = a.update(tick);
            assert_eq!(sets.active.len(), n, "linger {linger}: gone at tick {tick}");
            assert!(sets.entered.is_empty() && sets.left.is_empty());
        }
        let sets = a.update(11 + linger);
        assert!(sets.active.is_empty(), "linger {linger}: still active at tick {}", 11 + linger);
        assert_eq!(sets.left.len(), n);
        // Touching again within the linger restarts it.
        a.touch(s);
        a.update(100);
        a.touch(s);
        a.update(100 + linger);
        assert_eq!(a.update(100 + 2 * linger).active.len(), n);
        assert!(a.update(101 + 2 * linger).active.is_empty());
    }
}

#[test]
fn entered_and_left_follow_the_union() {
    let m = ventricle();
    let linger = 2;
    let mut a = Activation::new(m, linger);
    let mut rng = Lcg(3);
    let mut last: Vec<Option<u64>> = vec![None; m.n_regions()];
    let mut before: Vec<usize> = Vec::new();
    let mut start = m.n_regions() / 3;
    for tick in 0..60u64 {
        // A random walk of a few touched vertices.
        start = (start as i64 + (rng.next() * 6.0) as i64).clamp(0, m.n_regions() as i64 - 5) as usize;
        let k = (rng.next().abs() * 4.0) as usize;
        for (s, l) in last.iter_mut().enumerate().skip(start).take(k) {
            a.touch(s);
            *l = Some(tick);
        }
        let live: Vec<usize> = (0..m.n_regions()).filter(|&s| last[s].is_some_and(|t| tick - t <= linger)).collect();
        let want = naive_union(m, &live);
        let sets = a.update(tick);
        assert_eq!(sets.active, want.as_slice(), "tick {tick}");
        let entered: Vec<usize> = want.iter().copied().filter(|p| before.binary_search(p).is_err()).collect();
        let left: Vec<usize> = before.iter().copied().filter(|p| want.binary_search(p).is_err()).collect();
        assert_eq!(sets.entered, entered.as_slice(), "tick {tick}");
        assert_eq!(sets.left, left.as_slice(), "tick {tick}");
        before = want;
    }
    a.clear();
    assert!(a.active().is_empty() && a.active_regions().is_empty() && a.triangle_counts().iter().all(|&c| c == 0));
}

/// Tool centre pressing `depth` into the outer ellipsoid at angle `theta` around the axis, at
/// height `z` \[m\].
fn pressing(theta: f64, z: f64, radius: f64, depth: f64) -> Vec3 {
    let s = (1.0 - (z / OUTER[2]).powi(2)).sqrt();
    let p = Vec3::new(OUTER[0] * s * theta.cos(), OUTER[1] * s * theta.sin(), z);
    let n = Vec3::new(p.x / OUTER[0].powi(2), p.y / OUTER[1].powi(2), p.z / OUTER[2].powi(2)).normalize();
    p + (radius - depth) * n
}

/// A 5 mm tool pressed 1.5 mm and slid a quarter turn around the ventricle at mid height: the
/// active count stays between the largest touched region and the sum of the active regions,
/// and (reported) within the paper's 50-600.
#[test]
fn a_slide_keeps_the_active_count_within_the_regions() {
    let m = ventricle();
    let radius = 5e-3;
    for (linger, depth) in [(0u64, 1.5e-3), (20, 1.5e-3), (20, 3e-3)] {
        let mut a = Activation::new(m, linger);
        let (mut lo, mut hi, mut sum, mut ticks, mut changes) = (usize::MAX, 0, 0, 0, 0);
        let n = 2000;
        for tick in 0..n as u64 {
            let theta = 0.25 * std::f64::consts::FRAC_PI_2 + std::f64::consts::FRAC_PI_2 * tick as f64 / n as f64;
            let c = pressing(theta, 0.02, radius, depth);
            let touched = a.touch_sphere(&c, radius, 0.0, &m.outer_points);
            let sets = a.update(tick);
            if !sets.entered.is_empty() || !sets.left.is_empty() {
                changes += 1;
            }
            let k = sets.active.len();
            let regions = a.active_regions();
            let biggest = regions.iter().map(|&s| m.region_len(s as usize)).max().unwrap_or(0);
            let total: usize = regions.iter().map(|&s| m.region_len(s as usize)).sum();
            assert!(touched > 0, "tick {tick}: the tool touches no vertex");
            assert!(k >= biggest && k <= total, "tick {tick}: {k} active, regions give {biggest}..{total}");
            lo = lo.min(k);
            hi = hi.max(k);
            sum += k;
            ticks += 1;
            // The active triangles' list is the triangles some active region covers, each once,
            // after every update and in a restored copy.
            let want: Vec<u32> = (0..a.n_triangles() as u32).filter(|&t| a.is_triangle_active(t)).collect();
            let sorted = |x: &[u32]| {
                let mut v = x.to_vec();
                v.sort_unstable();
                v
            };
            assert_eq!(sorted(a.active_triangles()), want, "tick {tick}: the active triangles' list");
            if tick % 250 == 0 {
                let mut b = Activation::new(m, linger);
                b.restore(a.last_touched(), a.active_regions()).unwrap();
                assert_eq!(sorted(b.active_triangles()), want, "tick {tick}: restored");
                b.clear();
                assert!(b.active_triangles().is_empty());
                b.clone_from(&a);
                assert_eq!(sorted(b.active_triangles()), want, "tick {tick}: cloned");
            }
        }
        println!(
            "5 mm tool, {:.1} mm deep, linger {linger}: active particles min {lo} mean {:.0} max {hi} over {ticks} ticks, {changes} ticks with changes (paper: 50-600, mean 200)",
            depth * 1e3,
            sum as f64 / ticks as f64
        );
        assert!(lo >= 50, "fewer than 50 active particles");
    }
}

/// A tool wobbling +-1.5 mm along the surface at 50 Hz (a hand's tremor at 1 kHz ticks):
/// without hysteresis the regions at the patch's edge toggle every few ticks; with a linger of
/// one period nothing enters or leaves after the first period.
#[test]
fn hysteresis_stops_a_wobble_from_toggling_particles() {
    let m = ventricle();
    let radius = 5e-3;
    let period = 20u64;
    let mut changes = [0usize; 2];
    for (n, linger) in [0u64, period].into_iter().enumerate() {
        let mut a = Activation::new(m, linger);
        for tick in 0..10 * period {
            let phase = 2.0 * std::f64::consts::PI * tick as f64 / period as f64;
            let c = pressing(0.8 + 1.5e-3 / OUTER[0] * phase.sin(), 0.02, radius, 1.5e-3);
            a.touch_sphere(&c, radius, 0.0, &m.outer_points);
            let sets = a.update(tick);
            if tick >= period && (!sets.entered.is_empty() || !sets.left.is_empty()) {
                changes[n] += 1;
            }
        }
    }
    println!(
        "wobble: ticks with entering or leaving particles after the first period: {} without hysteresis, {} with a linger of {period} ticks",
        changes[0], changes[1]
    );
    assert!(changes[0] > 10, "the wobble does not change the regions ({})", changes[0]);
    assert_eq!(changes[1], 0);
}

// ------------------------------------------------------------------------------------------
// Confinement
// ------------------------------------------------------------------------------------------

/// Activation of region `s` alone.
fn only(m: &HybridModel, s: usize) -> Activation {
    let mut a = Activation::new(m, 0);
    a.touch(s);
    a.update(0);
    a
}

fn voxel_centre(f: &palpate_core::hybrid::RegionField, v: usize) -> Vec3 {
    let [nx, ny, _] = f.dims;
    f.origin + Vec3::new((v % nx) as f64 + 0.5, ((v / nx) % ny) as f64 + 0.5, (v / (nx * ny)) as f64 + 0.5) * f.h
}

/// Centre of an interior voxel of `f` (an anchor with no slack).
fn interior_anchor(f: &palpate_core::hybrid::RegionField) -> Vec3 {
    let v = (0..f.label.len())
        .find(|&v| f.label[v] == VoxelLabel::Inside)
        .or_else(|| (0..f.label.len()).find(|&v| f.label[v] == VoxelLabel::Boundary))
        .unwrap();
    voxel_centre(f, v)
}

#[test]
fn particles_inside_their_region_feel_no_wall() {
    let m = ventricle();
    let wall = Confinement::new(100.0);
    let (mut rest_inside, mut rest_slack, mut rest_anchored, mut rest_total) = (0, 0, 0, 0);
    for s in (0..m.n_regions()).step_by(97) {
        let a = only(m, s);
        let f = m.region_field(s);
        let anchor = interior_anchor(&f);
        for v in 0..f.label.len() {
            if f.label[v] != VoxelLabel::Outside {
                let p = wall.push(&m.grid, &m.voxel_owner, a.triangle_counts(), &voxel_centre(&f, v), &anchor);
                assert_eq!(p.placement, Placement::Inside, "region {s} voxel {v}");
                assert_eq!(p.force, Vec3::zeros());
            }
        }
        // The region's particles at rest (at their anchors): no force, though some rest in a
        // voxel another triangle owns, and a rare one (a particle whose own voxel is not a wall
        // voxel, given its triangle by projection) has none of its region's voxels within the
        // wall's reach: the wall then pulls it to its anchor, where it is.
        for &q in a.active() {
            rest_total += 1;
            let p = wall.push(&m.grid, &m.voxel_owner, a.triangle_counts(), &m.particles[q], &m.particles[q]);
            assert_eq!(p.force, Vec3::zeros(), "region {s} particle {q} at rest: {p:?}");
            match p.placement {
                Placement::Inside => rest_inside += 1,
                Placement::Slack => rest_slack += 1,
                Placement::Anchored => rest_anchored += 1,
                other => panic!("region {s} particle {q} at rest: {other:?}"),
            }
        }
    }
    println!(
        "voxel edge {:.3e} m (particle spacing {:.3e} m); rest particles of a lone active region: {rest_inside} in its voxels, {rest_slack} outside within their slack, {rest_anchored} with no voxel of it within reach, of {rest_total}",
        m.grid.h, m.spacing
    );
    assert!(rest_anchored * 200 <= rest_total, "{rest_anchored} of {rest_total} rest particles beyond their region's reach");
}

/// The tick skips the wall's search for a particle that stayed within its free radius of where
/// the tick started: no point within that radius may feel the wall (else the skip would change
/// the forces), and the radius must not be uselessly small for particles deep in a region.
/// A radius too large (e.g. forgetting the diagonal neighbours, or the cube beyond them) fails
/// the first check; one that ignores the slack fails on the particles resting outside.
#[test]
fn within_its_free_radius_a_particle_feels_no_wall() {
    let m = ventricle();
    let wall = Confinement::new(100.0);
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut tried, mut positive, mut deep) = (0, 0, 0);
    for s in (0..m.n_regions()).step_by(61) {
        let a = only(m, s);
        let counts = a.triangle_counts();
        for &q in a.active() {
            // Where a tick may start: around the rest position, a little moved.
            let x0 = m.particles[q] + (Vec3::new(uniform(), uniform(), uniform()) - Vec3::repeat(0.5)) * m.grid.h;
            let slack = wall.slack(&m.grid, &m.voxel_owner, counts, &m.particles[q]);
            let r = wall.free_radius(&m.grid, &m.voxel_owner, counts, &x0, slack);
            assert!(r >= 0.0 && r.is_finite());
            if r > 0.0 {
                positive += 1;
            }
            if r >= 0.5 * m.grid.h {
                deep += 1;
            }
            // (A zero radius skips nothing: the tick tests |x - x0| < r.)
            for _ in 0..if r > 0.0 { 8 } else { 0 } {
                // A point on the sphere of radius just under r: the worst place.
                let d = Vec3::new(uniform() - 0.5, uniform() - 0.5, uniform() - 0.5);
                if d.norm() == 0.0 {
                    continue;
                }
                let x = x0 + d.normalize() * (0.999 * r);
                let p = wall.push_with_slack(&m.grid, &m.voxel_owner, counts, &x, &m.particles[q], slack);
                assert_eq!(p.force, Vec3::zeros(), "region {s} particle {q}: free radius {r:.3e} m but {p:?} at {:.3e} m", (x - x0).norm());
                tried += 1;
            }
        }
    }
    println!("{tried} points within their free radius, none pushed; {positive} particles with a positive radius, {deep} of at least half a voxel");
    assert!(tried > 1000);
    assert!(deep * 4 > positive, "free radii are mostly tiny: {deep} of {positive} at least half a voxel");
}

/// Outside the region, the wall pushes back to the nearest voxel of the region: the distance is
/// exactly a brute-force search over region_field(s)'s labels (when within reach), and the
/// direction agrees with region_field(s)'s gradient (the offline B(p_s) field, which points to
/// the nearest *interior* voxel) on average.
#[test]
fn displaced_particles_are_pushed_back_along_the_region_field() {
    let m = ventricle();
    let wall = Confinement::new(100.0);
    let h = m.grid.h;
    let (mut n, mut cos_sum, mut forward, mut anchored, mut exact) = (0, 0.0, 0, 0, 0);
    for s in (0..m.n_regions()).step_by(53) {
        let a = only(m, s);
        let f = m.region_field(s);
        let anchor = interior_anchor(&f);
        let cubes: Vec<Vec3> = (0..f.label.len())
            .filter(|&v| f.label[v] != VoxelLabel::Outside)
            .map(|v| voxel_centre(&f, v) - Vec3::repeat(0.5 * h))
            .collect();
        for v in 0..f.label.len() {
            let g = f.gradient[v];
            if f.label[v] != VoxelLabel::Outside || g == [0.0; 3] {
                continue;
            }
            let x = voxel_centre(&f, v);
            let reference = cubes
                .iter()
                .map(|c| (x - Vec3::new(x.x.clamp(c.x, c.x + h), x.y.clamp(c.y, c.y + h), x.z.clamp(c.z, c.z + h))).norm())
                .fold(f64::INFINITY, f64::min);
            let p = wall.push(&m.grid, &m.voxel_owner, a.triangle_counts(), &x, &anchor);
            match p.placement {
                Placement::Outside => {}
                Placement::Anchored => {
                    assert!(reference > (wall.reach as f64 - 1.0) * h, "region {s} voxel {v}: anchored with the region {reference} m away");
                    anchored += 1;
                    continue;
                }
                other => panic!("region {s} voxel {v}: {other:?} outside the region"),
            }
            // Voxels of the region's triangles beyond its box may be nearer than the box's; the
            // search is exact up to (reach - 1) voxels.
            assert!(
                reference > (wall.reach as f64 - 1.0) * h || p.distance <= reference + 1e-12,
                "region {s} voxel {v}: {} m vs reference {reference} m",
                p.distance
            );
            if (p.distance - reference).abs() <= 1e-12 {
                exact += 1;
            }
            assert!(p.force.norm() > 0.0 && (p.force.norm() - wall.stiffness * p.distance).abs() < 1e-9);
            let gd = Vec3::new(g[0] as f64, g[1] as f64, g[2] as f64).normalize();
            let cos = p.force.normalize().dot(&gd);
            cos_sum += cos;
            if cos > 0.0 {
                forward += 1;
            }
            n += 1;
        }
    }
    let mean = cos_sum / n as f64;
    println!(
        "{n} outside voxels within reach (search exact to {} voxels): distance equal to the labels' brute force at {exact}; cos(force, region_field gradient) mean {mean:.3}, > 0 at {:.1}%; {anchored} beyond reach (anchored)",
        wall.reach - 1,
        100.0 * forward as f64 / n as f64
    );
    assert!(n > 1000);
    assert!(exact as f64 >= 0.9 * n as f64, "{exact} of {n} exact");
    assert!(mean > 0.7, "mean cos {mean}");
    assert!(forward as f64 >= 0.9 * n as f64, "{forward} of {n} forward");
}

#[test]
fn the_wall_force_is_minus_the_gradient_of_its_energy() {
    let m = ventricle();
    let wall = Confinement::new(250.0);
    let mut rng = Lcg(5);
    let (mut checked, mut kinks) = (0, 0);
    for s in (0..m.n_regions()).step_by(131) {
        let a = only(m, s);
        let tc = a.triangle_counts();
        let f = m.region_field(s);
        let inner = interior_anchor(&f);
        for v in 0..f.label.len() {
            if f.label[v] != VoxelLabel::Outside || v % 3 != 0 {
                continue;
            }
            let x = voxel_centre(&f, v) + 0.3 * m.grid.h * rng.vec();
            // Alternately no slack (anchor inside) and some slack (anchor half-way out).
            let anchor = if v % 2 == 0 { inner } else { x + 0.5 * (inner - x) };
            let p = wall.push(&m.grid, &m.voxel_owner, tc, &x, &anchor);
            if p.placement != Placement::Outside || p.energy < 1e-14 {
                continue;
            }
            let eps = 1e-9;
            let mut ok = true;
            for ax in 0..3 {
                let mut e = Vec3::zeros();
                e[ax] = eps;
                let ep = wall.push(&m.grid, &m.voxel_owner, tc, &(x + e), &anchor);
                let em = wall.push(&m.grid, &m.voxel_owner, tc, &(x - e), &anchor);
                let fd = -(ep.energy - em.energy) / (2.0 * eps);
                if (fd - p.force[ax]).abs() > 1e-5 * p.force.norm() + 1e-10 {
                    ok = false; // at a kink (two nearest cubes), the gradient is not defined
                }
            }
            if ok {
                checked += 1
            } else {
                kinks += 1
            }
        }
    }
    println!("energy consistency: {checked} points agree, {kinks} at kinks");
    assert!(checked > 100 && kinks * 20 <= checked, "{checked} agree, {kinks} do not");
}

#[test]
fn far_and_bad_particles_do_not_panic() {
    let m = ventricle();
    let a = only(m, 0);
    let wall = Confinement::new(100.0);
    let tc = a.triangle_counts();
    // Far away: pulled to the anchor.
    let x = Vec3::new(1.0, 1.0, 1.0);
    let anchor = m.particles[a.active()[0]];
    let p = wall.push(&m.grid, &m.voxel_owner, tc, &x, &anchor);
    assert_eq!(p.placement, Placement::Anchored);
    assert!((p.force + 100.0 * (x - anchor)).norm() < 1e-9);
    // Non-finite position or anchor: no force, counted.
    let nan = Vec3::new(f64::NAN, 0.0, 0.0);
    assert_eq!(wall.push(&m.grid, &m.voxel_owner, tc, &nan, &anchor).placement, Placement::Invalid);
    assert_eq!(wall.push(&m.grid, &m.voxel_owner, tc, &x, &nan).placement, Placement::Invalid);
    assert!(wall.nearest_allowed(&m.grid, &m.voxel_owner, tc, &nan).is_none());
    assert!(wall.slack(&m.grid, &m.voxel_owner, tc, &nan).is_nan());
    assert_eq!(wall.push_with_slack(&m.grid, &m.voxel_owner, tc, &x, &anchor, f64::NAN).placement, Placement::Invalid);
    let xs = [nan, x, anchor];
    let mut f = [Vec3::zeros(); 3];
    let sum = wall.apply(&m.grid, &m.voxel_owner, tc, &xs, &xs, None, &[0, 1, 2, 3], &mut f);
    assert_eq!(sum.invalid, 1);
    // Inconsistent grid / owners: anchored, no panic.
    let p = wall.push(&m.grid, &m.voxel_owner[..10], tc, &anchor, &x);
    assert!(matches!(p.placement, Placement::Anchored | Placement::Inside));
    let mut no = Activation::new(&HybridModel::default(), 3);
    no.touch(0);
    assert!(no.update(0).active.is_empty());
    assert_eq!(no.touch_sphere(&Vec3::zeros(), 1.0, 0.0, &[Vec3::zeros()]), 0);
}

// ------------------------------------------------------------------------------------------
// No allocation per tick
// ------------------------------------------------------------------------------------------

#[test]
fn the_per_tick_parts_allocate_nothing() {
    let m = ventricle();
    let tool = Tool::default();
    let wall = Confinement::new(100.0);
    let mut a = Activation::new(m, 10);
    let mut x = m.particles.clone();
    let v = vec![Vec3::new(0.0, 0.0, -0.01); x.len()];
    let mut f = vec![Vec3::zeros(); x.len()];
    let mut rng = Lcg(9);
    let mut slack = vec![0.0; x.len()];
    // Warm-up tick (nothing lazy is expected, but as robustness.rs does).
    a.touch_sphere(&pressing(0.5, 0.02, 5e-3, 2e-3), 5e-3, 1e-3, &m.outer_points);
    a.update(0);
    let before = allocations();
    let mut work = 0;
    let (mut t_act, mut t_forces, mut t_plain, mut t_slack, mut active_sum, mut pushed) = (0.0, 0.0, 0.0, 0.0, 0, 0);
    for tick in 1..300u64 {
        let c = pressing(0.5 + 0.002 * tick as f64, 0.02, 5e-3, 2e-3);
        let t0 = std::time::Instant::now();
        a.touch_sphere(&c, tool.radius, a.mean_edge(), &m.outer_points);
        let sets = a.update(tick);
        t_act += t0.elapsed().as_secs_f64();
        work += sets.active.len() + sets.entered.len() + sets.left.len();
        for &q in sets.active {
            x[q] = m.particles[q] + 0.6 * m.grid.h * rng.vec();
        }
        let active = a.active();
        let t0 = std::time::Instant::now();
        let s1 = tool.apply(&c, &Vec3::zeros(), &x, &v, active, &mut f);
        wall.slacks(&m.grid, &m.voxel_owner, a.triangle_counts(), &m.particles, active, &mut slack);
        let t1 = std::time::Instant::now();
        let s2 = wall.apply(&m.grid, &m.voxel_owner, a.triangle_counts(), &x, &m.particles, Some(&slack), active, &mut f);
        let t2 = std::time::Instant::now();
        let s3 = wall.apply(&m.grid, &m.voxel_owner, a.triangle_counts(), &x, &m.particles, None, active, &mut f);
        t_plain += t2.elapsed().as_secs_f64();
        assert_eq!((s2.pushed, s2.energy), (s3.pushed, s3.energy));
        t_slack += (t1 - t0).as_secs_f64();
        t_forces += (t2 - t1).as_secs_f64();
        active_sum += active.len();
        pushed += s2.pushed;
        work += s1.count + s2.pushed;
    }
    let n = allocations() - before;
    println!(
        "{n} allocations in 300 ticks ({work} items of work); per tick: touch + update {:.1} us, contact + confinement over {} active particles (all displaced by up to 0.6 voxel, {} pushed): contact + slacks {:.1} us once per tick, confinement {:.1} us per sub-step ({:.1} us without the slacks)",
        t_act / 299.0 * 1e6,
        active_sum / 299,
        pushed / 299,
        t_slack / 299.0 * 1e6,
        t_forces / 299.0 * 1e6,
        t_plain / 299.0 * 1e6
    );
    assert!(work > 0);
    assert_eq!(n, 0, "the per-tick parts allocated {n} times");
}

/// Every option is checked once, by name and unit (`SimOptions::check`, which `Sim::new` and the
/// binding call), and a long pause or linger is a count of ticks, not an overflow.
#[test]
fn options_are_checked_by_name() {
    let d = SimOptions::default();
    assert!(d.check().is_ok());
    let bad = [
        (SimOptions { max_tool_speed: 0.0, ..d }, "max_tool_speed [m/s]"),
        (SimOptions { max_tool_speed: f64::NAN, ..d }, "max_tool_speed [m/s]"),
        (SimOptions { linger: -0.1, ..d }, "linger [s]"),
        (SimOptions { linger: f64::INFINITY, ..d }, "linger [s]"),
        (SimOptions { shell_fallback: Some(f64::NAN), ..d }, "shell_pause (shell_fallback) [s]"),
        (SimOptions { activation_margin: -1e-3, ..d }, "activation_margin [m]"),
        (SimOptions { max_substeps: 0, ..d }, "max_substeps"),
        (SimOptions { mass_scaling: Some(1.5), ..d }, "mass_scaling quantile"),
        (SimOptions { core_contact_stiffness: 0.0, ..d }, "core_contact_stiffness [N/m]"),
        (SimOptions { support_spacings: 0.0, ..d }, "support_spacings [lattice spacings]"),
        (SimOptions { tool: ToolOptions { radius: -1.0, ..d.tool }, ..d }, "tool_radius [m]"),
    ];
    for (o, name) in bad {
        assert!(matches!(o.check(), Err(ModelError::Parameter { name: n, .. }) if n == name), "{name}: {:?}", o.check());
        assert!(matches!(Sim::new(ventricle().clone(), Material::myocardium(), o), Err(ModelError::Parameter { name: n, .. }) if n == name), "{name}");
    }
    // Finite but past any tick count: accepted (the counts saturate).
    assert!(SimOptions { linger: 1e300, shell_fallback: Some(1e300), ..d }.check().is_ok());
}
