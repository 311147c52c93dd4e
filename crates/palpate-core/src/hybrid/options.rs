//! The options of a build, their checks, and their section of the model file.

use super::file::{Reader, Res, Writer};
use super::model::HybridModel;
use super::transmural::Projection;
use crate::error::HybridError;

/// Particle spacing: a length, or the number of particles the shell should hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Spacing {
    /// Lattice spacing \[m\].
    Length(f64),
    /// About this many particles in the shell (the paper's ventricle has 27,988).
    Count(usize),
}

/// Options of [`super::build()`]. `Default` gives the paper's layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HybridOptions {
    /// Projection between the outer surface and the core.
    pub projection: Projection,
    /// Fraction of the wall thickness (in the transmural coordinate) that the FEM core takes,
    /// from the inner surface \[-\], in (0, 1).
    pub core_fraction: f64,
    /// Triangles of the simplified inner surface (each becomes `3 * core_layers` tets); 0:
    /// automatic, [`AUTO_CORE_TRIANGLES_CLOSED`] for a closed wall and
    /// [`AUTO_CORE_TRIANGLES_BASE`] for one with a base, raised by half (up to twice) while the
    /// core cannot be built without twisted prisms.
    pub core_triangles: usize,
    /// Prism layers of the core; 0 (the default): automatic, the core's height over its
    /// triangles' edge, so that its tets are about as tall as wide (one on the ventricles; see
    /// `core::auto_layers`).
    pub core_layers: usize,
    /// Particle spacing.
    pub spacing: Spacing,
    /// Density of the wall \[kg/m^3\] (particle masses; default the default tissue's,
    /// [`crate::material::Material::myocardium`]: 1060).
    pub density: f64,
    /// Fewest particles an activation region should hold: nv(p_s) grows by rings of triangles
    /// until RV(p_s) has at least this many (or [`MAX_RINGS`] rings).
    pub min_region_particles: usize,
    /// Wall voxels of the transmural solve (sets the voxel edge).
    pub field_voxels: usize,
    /// Compute the core's homogenised stiffness (default true; `super::homogenise`): the factor
    /// by which the runtime stiffens the core so that, where no particle is active, it bends as
    /// the whole wall does. False: the paper's core, stiff as the tissue (a model file keeps the
    /// table, not this flag: a loaded model says true when it has one).
    pub homogenise: bool,
}

/// Automatic core resolution of a closed wall: 900 tets, not the paper's 188 (Table 1). The
/// paper's 64 coarse triangles (192 tets here) cut chords deep into the ellipsoids' cavity: that
/// core holds 11% of the wall where half is asked, and the hybrid renders a third of the force of
/// the converged FEM under a sphere; 300 triangles hold 29% and render 17-28% below it with the
/// tissue's stiffness, within 12% once homogenised (VALIDATION.md, sphere indentation).
/// `core_triangles = 64` gives the paper's layout.
pub const AUTO_CORE_TRIANGLES_CLOSED: usize = 300;
/// Automatic core resolution of a wall with a base (valve rings and cut planes need more).
pub const AUTO_CORE_TRIANGLES_BASE: usize = 300;

/// Rings nv(p_s) may grow to.
pub const MAX_RINGS: usize = 12;

impl Default for HybridOptions {
    fn default() -> Self {
        HybridOptions {
            projection: Projection::Transmural,
            core_fraction: 0.5,
            core_triangles: 0,
            core_layers: 0,
            spacing: Spacing::Count(28_000),
            density: crate::material::Material::myocardium().density(),
            min_region_particles: 50,
            field_voxels: 120_000,
            homogenise: true,
        }
    }
}

/// Refuse options outside their ranges.
pub(super) fn check(o: &HybridOptions) -> Result<(), HybridError> {
    let bad = |name, value: f64, reason| Err(HybridError::Parameter { name, value, reason });
    if !(o.core_fraction > 0.0 && o.core_fraction < 1.0) {
        return bad("core fraction", o.core_fraction, "must lie strictly between 0 and 1");
    }
    if o.core_triangles != 0 && o.core_triangles < 4 {
        return bad("core triangles", o.core_triangles as f64, "must be at least 4");
    }
    if o.core_layers > 16 {
        return bad("core layers", o.core_layers as f64, "must be 0 (automatic) to 16");
    }
    match o.spacing {
        Spacing::Length(s) if !(s > 0.0 && s.is_finite()) => return bad("particle spacing", s, "must be positive and finite [m]"),
        Spacing::Count(n) if !(100..=50_000_000).contains(&n) => return bad("particle count", n as f64, "must be 100 to 5e7"),
        _ => {}
    }
    if !(o.density > 0.0 && o.density.is_finite()) {
        return bad("density", o.density, "must be positive and finite [kg/m^3]");
    }
    if !(1000..=50_000_000).contains(&o.field_voxels) {
        return bad("field voxels", o.field_voxels as f64, "must be 1e3 to 5e7");
    }
    Ok(())
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    let o = &m.options;
    w.u8(match o.projection {
        Projection::Transmural => 0,
        Projection::Radial => 1,
    });
    w.f64(o.core_fraction);
    w.u64(o.core_triangles as u64);
    w.u64(o.core_layers as u64);
    match o.spacing {
        Spacing::Length(s) => {
            w.u8(0);
            w.f64(s);
        }
        Spacing::Count(n) => {
            w.u8(1);
            w.u64(n as u64);
        }
    }
    w.f64(o.density);
    w.u64(o.min_region_particles as u64);
    w.u64(o.field_voxels as u64);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    let projection = match r.u8("projection")? {
        0 => Projection::Transmural,
        1 => Projection::Radial,
        x => return Err(r.corrupt(format!("projection code {x}"))),
    };
    let core_fraction = r.f64("core fraction")?;
    let core_triangles = r.u64("core triangles")? as usize;
    let core_layers = r.u64("core layers")? as usize;
    let spacing = match r.u8("spacing kind")? {
        0 => Spacing::Length(r.f64("spacing")?),
        1 => Spacing::Count(r.u64("spacing")? as usize),
        x => return Err(r.corrupt(format!("spacing code {x}"))),
    };
    m.options = HybridOptions {
        projection,
        core_fraction,
        core_triangles,
        core_layers,
        spacing,
        density: r.f64("density")?,
        min_region_particles: r.u64("min region particles")? as usize,
        field_voxels: r.u64("field voxels")? as usize,
        // Set from the homogenisation section, read after this one.
        homogenise: false,
    };
    Ok(())
}
