//! The core's homogenised stiffness: how much stiffer than the tissue the coarse core's material
//! must be for the core, where the shell is not simulated, to bend as the whole wall does.
//!
//! Why. The paper's core takes part of the wall's thickness (the core fraction) and is one or two
//! linear tets across it; the shell's particles carry stiffness only where they are active, near
//! the tool. Away from the tool the wall's global response (its bending and stretching under a
//! press) is the core's alone, and it is wrong twice: the core is thinner than the wall (softer)
//! and its linear tets lock in bending (stiffer). On the paper's ellipsoids with the default
//! 900-tet core the two leave the hybrid 23-28% below the converged FEM under a 15 mm sphere
//! (VALIDATION.md); the core fraction, not a resolution, set the answer. No choice of the core's
//! layout makes the two errors cancel on every wall.
//!
//! What. At build time, for a few Poisson's ratios, the wall's global compliance is computed twice
//! under the same loads: once for the whole wall with quadratic tets (the build's own prism mesh
//! spanning the wall at four times the core's resolution, one layer, [`crate::fem::small_strain`]: P2 does not
//! lock, and is within a few percent of a converged FEM on such a mesh), once for the core as the
//! runtime holds it, loaded through the skin's ties (the hybrid at rest, no particle active). The
//! loads are Hertz-like normal pressures `p(r) ~ sqrt(1 - r^2/a^2)` of radius `a` = 1.25 wall
//! thicknesses at [`PROBES`] points spread over the outer surface away from the held part (3 load
//! radii from it, or the quarter of the surface farthest from it on a block); the
//! compliance of a load is `f.u / |f|^2`. The core's stiffness factor is the geometric mean over
//! the probes of core compliance over wall compliance (its spread is kept and reported), and the
//! runtime multiplies the core's Lame constants and viscosities by it
//! ([`crate::runtime::SimOptions::homogenise`]), except under the active shell, whose particles
//! carry their share of the wall themselves (`runtime/homogenised_core.rs`).
//!
//! **Under the active shell** the core stands for the wall's inner part only, from the inner
//! surface to the core's outer faces, where the particles begin. The linear core is not that part
//! either: it locks (2.1x too stiff on the ellipsoids, 2.6x on Rodero, against the same core in
//! quadratic tets) and its simplified inner surface cuts the wall's inner layer off (softer). So
//! a second factor, the *active factor*, is computed the same way against that part: the build's
//! construction to the core's own transmural fraction, four times finer, one layer of quadratic
//! tets, and the linear core, both loaded by the same pressure on their outer faces under each
//! probe. The runtime brings the tets under the active shell to the tissue's stiffness times it
//! (0.61 on the paper's ellipsoids, 0.42 on Rodero, at nu = 0.4). With the tissue's own
//! stiffness there (a factor of 1, the rule before 2026-12-08) the linear core's locking stood in
//! for the compliance the core's geometry misses, and the ellipsoids' force was 11-24% above the
//! converged FEM (VALIDATION.md).
//!
//! Both factors come from the geometry and the material only (the same for any Young's modulus:
//! the compliances scale as 1/E); nothing is fitted to a reference curve. The local response
//! stays the particles' (their material is the tissue's).

use super::core;
use super::file::{Reader, Res, Writer};
use super::model::HybridModel;
use super::transmural::Transmural;
use super::wall::Wall;
use crate::error::HybridError;
use crate::fem::small_strain::{linear_surface_forces, surface_forces, Order, SmallStrain};
use crate::math::Vec3;
use crate::spatial::triangle_grid::closest_on_triangle;
use crate::spatial::TriangleGrid;
use std::time::Instant;

/// Poisson's ratios the factor is computed at; [`Homogenisation::factor`] interpolates between
/// them (linear tets lock more as nu nears 1/2) and clamps outside.
pub const POISSON_TABLE: [f64; 4] = [0.3, 0.4, 0.45, 0.49];

/// Probe loads over the outer surface.
pub const PROBES: usize = 8;

/// The reference wall's resolution: the core's triangle count times this (halved while its
/// prisms twist), [`REFERENCE_LAYERS`] layers of quadratic tets, the wall to this transmural
/// fraction. Measured on the paper's ellipsoids (900-tet core, nu = 0.4), the factor over the
/// refinements 1, 2, 4, 8 with two layers: 1.89, 2.02, 2.16, 2.21; with one layer at 4 and 8:
/// 2.19, 2.24 (what is left is the inner surface's chords; P2 one layer across bends within a
/// few percent of two): 4 and one layer cost 4 s for the four ratios.
pub const REFERENCE_REFINEMENT: usize = 4;
/// Layers of quadratic tets across the reference wall.
pub const REFERENCE_LAYERS: usize = 1;
/// The transmural fraction the reference wall reaches (1 is the outer surface itself, which the
/// core's builder does not take).
pub const REFERENCE_FRACTION: f64 = 0.999;

/// The load's radius in wall thicknesses.
pub const LOAD_RADIUS_THICKNESSES: f64 = 1.25;

/// The build's homogenisation of the core (empty: none, the paper's core, or a model file of
/// format 1).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Homogenisation {
    /// Poisson's ratios `(k)`.
    pub poisson: Vec<f64>,
    /// The core's stiffness factor at each `(k)` \[-\].
    pub factor: Vec<f64>,
    /// The smallest and largest per-probe factor at each `(k)` \[-\] (how uniform the correction
    /// is over the wall).
    pub spread: Vec<[f64; 2]>,
    /// The core's stiffness factor under the active shell at each `(k)` \[-\] (against the wall's
    /// inner part, up to the core's outer faces: see the module docs); empty in a model file of
    /// format 2 or older (the runtime then uses 1, the tissue's stiffness).
    pub active: Vec<f64>,
    /// The smallest and largest per-probe active factor at each `(k)` \[-\].
    pub active_spread: Vec<[f64; 2]>,
    /// Quadratic tets of the inner part's reference.
    pub region_tets: usize,
    /// Probe loads used.
    pub probes: usize,
    /// Quadratic tets of the reference wall.
    pub reference_tets: usize,
    /// The reference wall's triangles over the core's ([`REFERENCE_REFINEMENT`], or less where it
    /// twisted).
    pub refinement: usize,
    /// The load radius \[m\].
    pub load_radius: f64,
    /// Build time spent here \[s\].
    pub seconds: f64,
}

impl Homogenisation {
    /// The core's stiffness factor at Poisson's ratio `nu` (1 without a table).
    pub fn factor(&self, nu: f64) -> f64 {
        interpolate(&self.poisson, &self.factor, nu)
    }

    /// The core's stiffness factor under the active shell at Poisson's ratio `nu` (1, the
    /// tissue's, without a table).
    pub fn active_factor(&self, nu: f64) -> f64 {
        interpolate(&self.poisson, &self.active, nu)
    }

    /// True when the build computed a table.
    pub fn is_empty(&self) -> bool {
        self.poisson.is_empty()
    }
}

/// `f` at `nu`, linear between the table's ratios `p` and clamped outside (1 without a table).
fn interpolate(p: &[f64], f: &[f64], nu: f64) -> f64 {
    if p.is_empty() || p.len() != f.len() {
        return 1.0;
    }
    if nu <= p[0] {
        return f[0];
    }
    for k in 1..p.len() {
        if nu <= p[k] {
            let t = (nu - p[k - 1]) / (p[k] - p[k - 1]);
            return f[k - 1] + t * (f[k] - f[k - 1]);
        }
    }
    f[p.len() - 1]
}

/// The height \[m\] at or below which the runtime holds a closed wall's core nodes: `fraction`
/// of the core's height above its lowest point.
pub fn held_cut(points: &[Vec3], fraction: f64) -> f64 {
    let lo = points.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
    let hi = points.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
    lo + fraction * (hi - lo)
}

/// Fraction of a closed wall's core height held by the runtime (`runtime::Sim::new`).
pub const CLOSED_HOLD_FRACTION: f64 = 0.3;

/// Lame constants of Young's modulus 1 Pa and Poisson's ratio `nu` (compliances scale as 1/E).
fn unit_lame(nu: f64) -> (f64, f64) {
    (nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), 1.0 / (2.0 * (1.0 + nu)))
}

/// Compute the homogenisation of the built core of `m` (core, outer surface and skin present).
pub(super) fn compute(m: &HybridModel, wall: &Wall, field: &Transmural, wall_grid: &TriangleGrid) -> Result<Homogenisation, HybridError> {
    let t0 = Instant::now();
    // The whole wall (the build's own prism mesh to the outer surface) and the wall's inner part
    // (the same construction to the core's own fraction): finer, in quadratic tets.
    let (reference, refinement) = finer_core(m, wall, field, wall_grid, REFERENCE_FRACTION, "the reference wall mesh")?;
    let (region, _) = finer_core(m, wall, field, wall_grid, m.options.core_fraction, "the wall's inner part")?;

    let closed = m.core_base_nodes.is_empty();
    let cut = held_cut(&m.core_points, CLOSED_HOLD_FRACTION);
    let held = |points: &[Vec3], base: &[usize]| -> Vec<bool> {
        if closed {
            points.iter().map(|p| p.z <= cut).collect()
        } else {
            let mut h = vec![false; points.len()];
            for &b in base {
                h[b] = true;
            }
            h
        }
    };
    let core_held = held(&m.core_points, &m.core_base_nodes);
    let ref_held = held(&reference.core_points, &reference.core_base_nodes);
    let region_held = held(&region.core_points, &region.core_base_nodes);

    let thickness = m.wall_volume / outer_area(m).max(f64::MIN_POSITIVE);
    let a = LOAD_RADIUS_THICKNESSES * thickness;
    let probes = probe_vertices(m, &core_held, a)?;
    let normals = vertex_normals(m);
    // Each probe's centre on the core's outer faces: where the active shell presses on the core.
    let on_core: Vec<Vec3> = probes.iter().map(|&v| nearest_on_faces(&m.core_points, &m.core_faces, &m.outer_points[v])).collect();

    let mut out = Homogenisation { probes: probes.len(), load_radius: a, refinement, ..Homogenisation::default() };
    for nu in POISSON_TABLE {
        let (lambda, mu) = unit_lame(nu);
        let stiffness = |r: &HybridModel, held: &[bool], order: Order, what: &str| {
            SmallStrain::new(&r.core_points, &r.core_tets, order, lambda, mu, held).map_err(|e| fail(format!("{what}'s stiffness: {e}")))
        };
        let wall_k = stiffness(&reference, &ref_held, Order::Quadratic, "the reference wall")?;
        let region_k = stiffness(&region, &region_held, Order::Quadratic, "the wall's inner part")?;
        let core_k = stiffness(m, &core_held, Order::Linear, "the core")?;
        (out.reference_tets, out.region_tets) = (wall_k.n_tets(), region_k.n_tets());
        let mut ratios = Vec::with_capacity(probes.len());
        let mut active = Vec::with_capacity(probes.len());
        for (k, &v) in probes.iter().enumerate() {
            let n = normals[v];
            // The whole wall, loaded on its outer faces; the core, loaded on the skin and
            // through its ties (no particle active).
            let at_skin = pressure(m.outer_points[v], n, a);
            let mut f = vec![Vec3::zeros(); wall_k.nodes().len()];
            surface_forces(&wall_k, &reference.core_faces, a / 8.0, at_skin, &mut f);
            let mut fs = vec![Vec3::zeros(); m.outer_points.len()];
            linear_surface_forces(&m.outer_points, &m.outer_tris, a / 8.0, at_skin, &mut fs);
            let mut fc = vec![Vec3::zeros(); m.core_points.len()];
            for (s, fv) in fs.iter().enumerate() {
                let face = m.core_faces[m.skin_face[s] as usize];
                for i in 0..3 {
                    fc[face[i]] += fv * m.skin_bary[s][i];
                }
            }
            ratios.push(ratio(compliance(&core_k, &fc), compliance(&wall_k, &f), v)?);
            // Under the active shell: the wall's inner part and the core, each pressed on its
            // outer faces under the probe.
            let at_core = pressure(on_core[k], n, a);
            let mut fr = vec![Vec3::zeros(); region_k.nodes().len()];
            surface_forces(&region_k, &region.core_faces, a / 8.0, at_core, &mut fr);
            let mut fd = vec![Vec3::zeros(); m.core_points.len()];
            linear_surface_forces(&m.core_points, &m.core_faces, a / 8.0, at_core, &mut fd);
            active.push(ratio(compliance(&core_k, &fd), compliance(&region_k, &fr), v)?);
        }
        out.poisson.push(nu);
        let (mean, spread) = geometric_mean(&ratios);
        out.factor.push(mean);
        out.spread.push(spread);
        let (mean, spread) = geometric_mean(&active);
        out.active.push(mean);
        out.active_spread.push(spread);
    }
    out.seconds = t0.elapsed().as_secs_f64();
    Ok(out)
}

fn fail(what: String) -> HybridError {
    HybridError::Core(format!("homogenisation of the core: {what}"))
}

/// The build's prism mesh of `m`'s wall to the transmural `fraction`, one layer, at
/// [`REFERENCE_REFINEMENT`] times the core's triangles (halved while its prisms twist, as on a
/// wall as irregular as Rodero's at fine levels); returns it and the refinement used.
fn finer_core(
    m: &HybridModel,
    wall: &Wall,
    field: &Transmural,
    wall_grid: &TriangleGrid,
    fraction: f64,
    what: &str,
) -> Result<(HybridModel, usize), HybridError> {
    let mut r = HybridModel { options: m.options, ..HybridModel::default() };
    r.options.core_fraction = fraction;
    r.options.core_layers = REFERENCE_LAYERS;
    let mut refinement = REFERENCE_REFINEMENT;
    loop {
        r.options.core_triangles = refinement * m.core_faces.len().max(1);
        match core::build(&mut r, wall, field, wall_grid) {
            Ok(()) => return Ok((r, refinement)),
            Err(HybridError::TwistedCore { .. }) if refinement > 1 => refinement /= 2,
            Err(e) => return Err(fail(format!("{what} ({} triangles): {e}; build with homogenise off for the paper's core", r.options.core_triangles))),
        }
    }
}

/// Probes: outer vertices farther than 3 load radii `a` from the held part, spread by
/// farthest-point sampling (on a block as thick as it is wide, a slab held at its sides: the
/// quarter of the outer vertices farthest from the held part).
fn probe_vertices(m: &HybridModel, core_held: &[bool], a: f64) -> Result<Vec<usize>, HybridError> {
    let held_points: Vec<Vec3> = (0..m.core_points.len()).filter(|&i| core_held[i]).map(|i| m.core_points[i]).collect();
    let dist_to_held = |p: Vec3| held_points.iter().map(|q| (p - q).norm()).fold(f64::INFINITY, f64::min);
    let mut candidates: Vec<usize> = (0..m.outer_points.len()).filter(|&v| dist_to_held(m.outer_points[v]) > 3.0 * a).collect();
    if candidates.len() < PROBES {
        let mut by_distance: Vec<(f64, usize)> = (0..m.outer_points.len()).map(|v| (dist_to_held(m.outer_points[v]), v)).collect();
        by_distance.sort_by(|x, y| y.0.total_cmp(&x.0));
        candidates = by_distance.iter().take((by_distance.len() / 4).max(PROBES.min(by_distance.len()))).map(|&(_, v)| v).collect();
    }
    if candidates.is_empty() {
        return Err(fail("the outer surface has no vertex".into()));
    }
    Ok(farthest_points(&m.outer_points, &candidates, PROBES, dist_to_held))
}

/// A Hertz-like normal pressure of unit peak and radius `a` centred at `c`, pressing along `-n`.
fn pressure(c: Vec3, n: Vec3, a: f64) -> impl Fn(Vec3) -> Vec3 + Copy {
    move |x: Vec3| {
        let r2 = (x - c).norm_squared() / (a * a);
        if r2 < 1.0 {
            -n * (1.0 - r2).sqrt()
        } else {
            Vec3::zeros()
        }
    }
}

/// The point of the triangles `faces` over `points` nearest to `p`.
fn nearest_on_faces(points: &[Vec3], faces: &[[usize; 3]], p: &Vec3) -> Vec3 {
    let mut best = (f64::INFINITY, *p);
    for t in faces {
        let (q, _) = closest_on_triangle(p, &points[t[0]], &points[t[1]], &points[t[2]]);
        let d = (q - p).norm_squared();
        if d < best.0 {
            best = (d, q);
        }
    }
    best.1
}

/// `core / reference`, both positive and finite, or an error naming the probe's outer vertex.
fn ratio(core: f64, reference: f64, v: usize) -> Result<f64, HybridError> {
    if core > 0.0 && reference > 0.0 && core.is_finite() && reference.is_finite() {
        Ok(core / reference)
    } else {
        Err(fail(format!("compliance of the probe at outer vertex {v}: reference {reference:e}, core {core:e}")))
    }
}

/// The geometric mean of positive `x` and its smallest and largest value.
fn geometric_mean(x: &[f64]) -> (f64, [f64; 2]) {
    let mean = (x.iter().map(|r| r.ln()).sum::<f64>() / x.len() as f64).exp();
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(0.0, f64::max);
    (mean, [lo, hi])
}

/// `f.u / |sum f|^2` \[m/N per Pa of Young's modulus\].
fn compliance(k: &SmallStrain, f: &[Vec3]) -> f64 {
    let u = k.solve(f);
    let total: Vec3 = f.iter().sum();
    f.iter().zip(&u).map(|(f, u)| f.dot(u)).sum::<f64>() / total.norm_squared()
}

fn outer_area(m: &HybridModel) -> f64 {
    m.outer_tris
        .iter()
        .map(|t| 0.5 * (m.outer_points[t[1]] - m.outer_points[t[0]]).cross(&(m.outer_points[t[2]] - m.outer_points[t[0]])).norm())
        .sum()
}

fn vertex_normals(m: &HybridModel) -> Vec<Vec3> {
    let mut n = vec![Vec3::zeros(); m.outer_points.len()];
    for t in &m.outer_tris {
        let w = (m.outer_points[t[1]] - m.outer_points[t[0]]).cross(&(m.outer_points[t[2]] - m.outer_points[t[0]]));
        for &i in t {
            n[i] += w;
        }
    }
    n.iter().map(|v| v.try_normalize(0.0).unwrap_or_else(Vec3::zeros)).collect()
}

/// `k` of `candidates` spread over `points`: the farthest from the held part first, then each the
/// farthest from those chosen.
fn farthest_points(points: &[Vec3], candidates: &[usize], k: usize, first_key: impl Fn(Vec3) -> f64) -> Vec<usize> {
    let mut chosen = vec![*candidates.iter().max_by(|&&a, &&b| first_key(points[a]).total_cmp(&first_key(points[b]))).unwrap_or(&candidates[0])];
    let mut d: Vec<f64> = candidates.iter().map(|&c| (points[c] - points[chosen[0]]).norm()).collect();
    while chosen.len() < k.min(candidates.len()) {
        let (j, _) = d.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap_or((0, &0.0));
        let c = candidates[j];
        chosen.push(c);
        for (i, &q) in candidates.iter().enumerate() {
            d[i] = d[i].min((points[q] - points[c]).norm());
        }
    }
    chosen
}

/// The homogenisation's section of the model file (format 2; a format-1 file has none).
pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    let h = &m.homogenisation;
    w.f64s(&h.poisson);
    w.f64s(&h.factor);
    w.rows(&h.spread, |w, x| w.f64(x));
    w.u64(h.probes as u64);
    w.u64(h.reference_tets as u64);
    w.u64(h.refinement as u64);
    w.f64(h.load_radius);
    w.f64(h.seconds);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    let poisson = r.f64s("homogenisation Poisson's ratios")?;
    let factor = r.f64s("homogenisation factors")?;
    let spread = r.rows(8, "homogenisation spread", |r| r.f64("homogenisation spread"))?;
    let probes = r.u64("homogenisation probes")? as usize;
    let reference_tets = r.u64("homogenisation reference tets")? as usize;
    let refinement = r.u64("homogenisation refinement")? as usize;
    let load_radius = r.f64("homogenisation load radius")?;
    let seconds = r.f64("homogenisation time")?;
    // The active factor is the next section's (format 3).
    m.homogenisation = Homogenisation { poisson, factor, spread, probes, reference_tets, refinement, load_radius, seconds, ..Homogenisation::default() };
    m.options.homogenise = !m.homogenisation.is_empty();
    Ok(())
}

/// The active factor's section (format 3; a file of format 2 or older has none, and its model
/// keeps the tissue's stiffness under the active shell).
pub(super) fn write_active(m: &HybridModel, w: &mut Writer) {
    let h = &m.homogenisation;
    w.f64s(&h.active);
    w.rows(&h.active_spread, |w, x| w.f64(x));
    w.u64(h.region_tets as u64);
}

#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read_active(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    let h = &mut m.homogenisation;
    h.active = r.f64s("homogenisation active factors")?;
    h.active_spread = r.rows(8, "homogenisation active spread", |r| r.f64("homogenisation active spread"))?;
    h.region_tets = r.u64("homogenisation inner part's tets")? as usize;
    Ok(())
}

/// A table the runtime can use: as many factors as ratios, ratios increasing in (-1, 1/2), factors
/// positive and finite (a crafted file could otherwise make the core's material invalid).
pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    let h = &m.homogenisation;
    if h.factor.len() != h.poisson.len() || h.spread.len() != h.poisson.len() {
        return Err(format!("homogenisation: {} Poisson's ratios, {} factors, {} spreads", h.poisson.len(), h.factor.len(), h.spread.len()));
    }
    if !h.poisson.iter().all(|&nu| nu > -1.0 && nu < 0.5) || !h.poisson.windows(2).all(|w| w.first() < w.last()) {
        return Err(format!("homogenisation: Poisson's ratios {:?} must increase within (-1, 0.5)", h.poisson));
    }
    if !(h.active.is_empty() || (h.active.len() == h.poisson.len() && h.active_spread.len() == h.poisson.len())) {
        return Err(format!(
            "homogenisation: {} Poisson's ratios, {} active factors, {} active spreads",
            h.poisson.len(),
            h.active.len(),
            h.active_spread.len()
        ));
    }
    // A factor of 1e-3..1e3: far outside, the core would not be the wall's (the build gives 0.3-3).
    let all = h.factor.iter().chain(h.spread.iter().flatten()).chain(&h.active).chain(h.active_spread.iter().flatten());
    if !all.clone().all(|&f| (1e-3..=1e3).contains(&f)) {
        return Err(format!("homogenisation: factors {:?} and active factors {:?} must lie in [1e-3, 1e3]", h.factor, h.active));
    }
    if !(h.load_radius.is_finite() && h.load_radius >= 0.0 && h.seconds.is_finite() && h.seconds >= 0.0) {
        return Err("homogenisation: load radius and time must be finite and non-negative".into());
    }
    Ok(())
}
