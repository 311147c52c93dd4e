//! The particle shell Omega_p (paper §4): lattice points inside the wall and outside the core,
//! each tied to the outer triangle above it and the core face below it along its field line,
//! sorted by that outer triangle; the projections along field lines; the shell's section of the
//! model file.

use super::file::{finite, in_range, Reader, Res, Writer};
use super::model::HybridModel;
use super::options::{HybridOptions, Spacing};
use super::region_field::VOXEL_CORE;
use super::transmural::Transmural;
use super::wall::Wall;
use crate::error::HybridError;
use crate::math::Vec3;
use crate::mesh::sample_inside;
use crate::spatial::{csr, Nearest, TetGrid, TriangleGrid};

/// Lattice spacing \[m\] of the options, given the wall's and the core's volume \[m^3\].
pub(super) fn spacing(o: &HybridOptions, wall_volume: f64, core_volume: f64) -> f64 {
    match o.spacing {
        Spacing::Length(s) => s,
        Spacing::Count(n) => ((wall_volume - core_volume).max(0.05 * wall_volume) / n as f64).cbrt(),
    }
}

/// The lattice points of spacing `spacing` inside the wall and outside the core.
pub(super) fn lattice(wall: &Wall, core_points: &[Vec3], core_grid: &TetGrid, spacing: f64, density: f64) -> Result<Vec<Vec3>, HybridError> {
    let fill = sample_inside(&wall.surface, spacing, density)?;
    let mut particles = Vec::with_capacity(fill.len());
    for p in &fill.positions {
        if core_grid.locate(core_points, p).is_none() {
            particles.push(*p);
        }
    }
    if particles.is_empty() {
        return Err(HybridError::Particles(format!("no lattice point of spacing {spacing:e} m lies in the shell between the core and the outer surface")));
    }
    Ok(particles)
}

/// Where a point's field line meets the core: the core face, the point on it and its
/// barycentric coordinates.
pub(super) struct CoreHit {
    pub face: u32,
    pub point: Vec3,
    pub bary: [f64; 3],
}

/// Projections along the field lines (or radial lines) to the outer surface and to the core of
/// a model (its options, core and outer surface); where the line cannot be followed, the nearest
/// point is taken and a fallback counted.
pub(super) struct Projector<'a> {
    pub field: &'a Transmural,
    /// Nearest-triangle grids of the outer surface and of the core's faces.
    pub outer_grid: TriangleGrid,
    pub core_face_grid: TriangleGrid,
}

impl Projector<'_> {
    /// The outer triangle above `p`.
    pub fn outer_of(&self, m: &HybridModel, p: &Vec3, fallbacks: &mut usize) -> u32 {
        let top = 1.0 - 1e-6;
        let q = self.field.march_to_level(p, top, true, m.options.projection).unwrap_or_else(|| {
            *fallbacks += 1;
            *p
        });
        self.outer_grid.nearest(&m.outer_points, &m.outer_tris, &q, |_| true).map(|r| r.triangle as u32).unwrap_or(0)
    }

    /// The core face below `p`.
    pub fn core_of(&self, m: &HybridModel, p: &Vec3, fallbacks: &mut usize) -> CoreHit {
        let q = self.field.march_to_level(p, m.options.core_fraction, false, m.options.projection).unwrap_or_else(|| {
            *fallbacks += 1;
            *p
        });
        let Nearest { triangle, point, bary, .. } = self.core_face_grid.nearest(&m.core_points, &m.core_faces, &q, |_| true).expect("the core has faces");
        CoreHit { face: triangle as u32, point, bary }
    }
}

/// How many particles fell back to the nearest point: towards the outer surface, the core.
pub(super) struct Fallbacks {
    pub outer: usize,
    pub core: usize,
}

/// The shell fields of `m` from `particles` at `spacing` \[m\], sorted by the outer triangle
/// above them: each takes its voxel's owner (so that RV(p_s) and the inside voxels of B(p_s)
/// agree; the voxels are built first), or marches when its voxel is not a wall voxel.
pub(super) fn assign(m: &mut HybridModel, particles: Vec<Vec3>, spacing: f64, project: &Projector) -> Fallbacks {
    let grid = &m.grid;
    let mut fo = 0;
    let mut fc = 0;
    let mut keyed: Vec<(u32, u32, Vec3)> = particles
        .iter()
        .map(|p| {
            let from_voxel = grid.cell_of(p).map(|a| m.voxel_owner[grid.index_of(a)]).filter(|&w| w < VOXEL_CORE);
            let t = match from_voxel {
                Some(w) => w,
                None => project.outer_of(m, p, &mut fo),
            };
            (t, project.core_of(m, p, &mut fc).face, *p)
        })
        .collect();
    keyed.sort_by(|a, b| a.0.cmp(&b.0).then(a.2.x.total_cmp(&b.2.x)).then(a.2.y.total_cmp(&b.2.y)).then(a.2.z.total_cmp(&b.2.z)));
    m.spacing = spacing;
    m.particles = keyed.iter().map(|k| k.2).collect();
    m.particle_outer_tri = keyed.iter().map(|k| k.0).collect();
    m.particle_core_face = keyed.iter().map(|k| k.1).collect();
    m.tri_particle_ptr = csr::offsets(m.outer_tris.len(), m.particle_outer_tri.iter().map(|&t| t as usize));
    m.particle_mass = vec![m.options.density * spacing.powi(3); m.particles.len()];
    Fallbacks { outer: fo, core: fc }
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.f64(m.spacing);
    w.vec3s(&m.particles);
    w.f64s(&m.particle_mass);
    w.u32s(&m.particle_outer_tri);
    w.u32s(&m.particle_core_face);
    w.u32s(&m.tri_particle_ptr);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.spacing = r.f64("spacing")?;
    m.particles = r.vec3s("particles")?;
    m.particle_mass = r.f64s("particle masses")?;
    m.particle_outer_tri = r.u32s("particle outer triangles")?;
    m.particle_core_face = r.u32s("particle core faces")?;
    m.tri_particle_ptr = r.u32s("particles per outer triangle")?;
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    let (np, nt, nf) = (m.particles.len(), m.outer_tris.len(), m.core_faces.len());
    if m.particle_mass.len() != np || m.particle_outer_tri.len() != np || m.particle_core_face.len() != np {
        return Err("per-particle arrays of different lengths".into());
    }
    in_range("particle outer triangles", m.particle_outer_tri.iter().map(|&x| x as usize), nt)?;
    in_range("particle core faces", m.particle_core_face.iter().map(|&x| x as usize), nf)?;
    let ptr = &m.tri_particle_ptr;
    if ptr.len() != nt + 1 || ptr.first() != Some(&0) || ptr.last().map(|&x| x as usize) != Some(np) || ptr.windows(2).any(|w| w[0] > w[1]) {
        return Err(format!("particles per outer triangle: offset table inconsistent ({} entries for {nt} rows over {np} items)", ptr.len()));
    }
    finite("particles", &m.particles)
}
