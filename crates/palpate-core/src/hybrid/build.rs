//! Building the hybrid model (paper §4 and §6) from the surfaces of an organ wall.
//!
//! ```text
//! wall boundary (closed, parts inner/outer/base)
//!   ├─ transmural field phi on wall voxels ............................ transmural.rs
//!   ├─ FEM core Omega_e: inner surface simplified (quadric collapse), offset along the field
//!   │  to phi = f (the core fraction) in L layers; prisms split into 3 tets each, consistently
//!   ├─ particles Omega_p: lattice points inside the wall and outside the core
//!   ├─ per particle: the outer triangle above it and the core face below it (field lines)
//!   ├─ per outer vertex p_s: nv(p_s) (its triangles, grown by rings until enough particles),
//!   │  RV(p_s) (the particles under those triangles), C(p_s) (the projections of nv's
//!   │  boundary onto the core), the core faces under RV, and the box B(p_s) in the shared voxels
//!   └─ skin: each outer vertex tied to the core face its projection hits (barycentric, offset)
//! ```
//!
//! Each stage lives in its part's module (core.rs, shell.rs, region_field.rs, skin.rs,
//! regions.rs); this is the order they run in and what they are timed by.

use super::file::{Reader, Res, Writer};
use super::model::HybridModel;
use super::shell::Projector;
use super::transmural;
use super::{core, homogenise, options, order, outer, region_field, regions, shell, skin};
use crate::error::HybridError;
use crate::spatial::{TetGrid, TriangleGrid};
use std::time::Instant;

// The paths these had when they lived here.
pub use super::core::CoreQuality;
pub use super::options::{HybridOptions, Spacing, AUTO_CORE_TRIANGLES_BASE, AUTO_CORE_TRIANGLES_CLOSED, MAX_RINGS};
pub use super::region_field::{RegionField, VoxelLabel, VOXEL_CORE, VOXEL_OUTSIDE};
pub use super::wall::{Wall, MIN_PIECE_VOLUME};

/// Where the build spent its time \[s\] and how the projections went.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BuildStats {
    pub field_s: f64,
    pub core_s: f64,
    pub particles_s: f64,
    pub regions_s: f64,
    pub total_s: f64,
    /// Conjugate-gradient iterations of the transmural solve.
    pub field_iterations: usize,
    /// Projections that could not follow the chosen mode and fell back to the nearest point
    /// (radial lines that leave and re-enter the wall, field lines that exit through a base):
    /// particles to the outer surface, particles to the core, outer vertices to the core.
    pub fallback_particle_outer: usize,
    pub fallback_particle_core: usize,
    pub fallback_skin: usize,
}

/// Build the hybrid model of `wall`.
pub fn build(wall: &Wall, o: &HybridOptions) -> Result<HybridModel, HybridError> {
    options::check(o)?;
    let t_start = Instant::now();
    let mut stats = BuildStats::default();
    let surf = &wall.surface;
    let wall_volume = surf.volume();
    if !(wall_volume > 0.0) {
        return Err(HybridError::Parts(format!("the wall boundary encloses {wall_volume:e} m^3; is it oriented outward?")));
    }
    // --- transmural field ---
    let h = (wall_volume / o.field_voxels as f64).cbrt();
    // The voxel grid spans the wall's bounding box, sized by the wall's volume: a thin wall (or
    // a wrongly scaled surface) makes the box hold 1e4x more voxels than the wall. Refused over
    // the memory budget before it is taken (~40 bytes a voxel in the field solve).
    let (lo, hi) = surf.bounding_box();
    let dims = (hi - lo).map(|e| (e + 4.0 * h) / h);
    crate::limits::check_grid(
        &format!("transmural voxel grid ({:.0} x {:.0} x {:.0} voxels of {h:.3e} m for a wall of {wall_volume:.3e} m^3: the wall is thin for its bounding box; lower field_voxels)", dims.x, dims.y, dims.z),
        [dims.x, dims.y, dims.z],
        40.0,
    )?;
    let mean_edge = (surf.area() / surf.n_triangles() as f64 * 2.3).sqrt();
    let wall_grid = TriangleGrid::new(surf.points(), surf.triangles(), mean_edge.max(0.5 * h));
    let field = transmural::solve(surf, &wall.parts, h, &wall_grid);
    stats.field_iterations = field.iterations;
    stats.field_s = t_start.elapsed().as_secs_f64();

    let mut m = HybridModel { options: *o, wall_volume, ..HybridModel::default() };

    // --- FEM core ---
    let t0 = Instant::now();
    core::build(&mut m, wall, &field, &wall_grid)?;
    stats.core_s = t0.elapsed().as_secs_f64();

    // --- particles, and the shared voxels they take their outer triangle from ---
    let t0 = Instant::now();
    let spacing = shell::spacing(o, wall_volume, m.core_volume());
    // Each particle costs the build and the model ~600 bytes (position, mass, owners, regions,
    // neighbour searches): refused over the budget before the lattice is filled.
    let estimate = (wall_volume - m.core_volume()).max(0.0) / (spacing * spacing * spacing);
    crate::limits::check(&format!("particle shell of about {estimate:.3e} particles at spacing {spacing:e} m"), estimate, 600.0)?;
    let core_grid = TetGrid::new(&m.core_points, &m.core_tets, 2.0 * spacing.max(h));
    let particles = shell::lattice(wall, &m.core_points, &core_grid, spacing, o.density)?;
    outer::build(&mut m, wall);
    let project = Projector {
        field: &field,
        outer_grid: outer::grid(&m, 0.5 * h),
        core_face_grid: TriangleGrid::new(&m.core_points, &m.core_faces, 2.0 * h.max(spacing)),
    };
    region_field::owners(&mut m, &field, &core_grid, &project);
    let fallbacks = shell::assign(&mut m, particles, spacing, &project);
    stats.fallback_particle_outer = fallbacks.outer;
    stats.fallback_particle_core = fallbacks.core;
    stats.particles_s = t0.elapsed().as_secs_f64();

    // --- skin, and the activation regions ---
    let t0 = Instant::now();
    stats.fallback_skin = skin::build(&mut m, &project);
    regions::build(&mut m);
    order::apply(&mut m);
    stats.regions_s = t0.elapsed().as_secs_f64();

    // --- the core's homogenised stiffness ---
    if o.homogenise {
        m.homogenisation = homogenise::compute(&m, wall, &field, &wall_grid)?;
    }
    stats.total_s = t_start.elapsed().as_secs_f64();
    m.stats = stats;
    Ok(m)
}

pub(super) fn write_stats(m: &HybridModel, w: &mut Writer) {
    let s = &m.stats;
    for x in [s.field_s, s.core_s, s.particles_s, s.regions_s, s.total_s] {
        w.f64(x);
    }
    for x in [s.field_iterations, s.fallback_particle_outer, s.fallback_particle_core, s.fallback_skin] {
        w.u64(x as u64);
    }
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read_stats(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    let mut t = [0.0; 5];
    for x in t.iter_mut() {
        *x = r.f64("build statistics")?;
    }
    let mut c = [0usize; 4];
    for x in c.iter_mut() {
        *x = r.u64("build statistics")? as usize;
    }
    m.stats = BuildStats {
        field_s: t[0],
        core_s: t[1],
        particles_s: t[2],
        regions_s: t[3],
        total_s: t[4],
        field_iterations: c[0],
        fallback_particle_outer: c[1],
        fallback_particle_core: c[2],
        fallback_skin: c[3],
    };
    Ok(())
}
