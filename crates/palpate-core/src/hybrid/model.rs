//! The compiled hybrid model: its fields (one flat struct, as the binding and the runtime read
//! them; each part's module builds, writes, reads and checks its own fields) and the wall's
//! section of the model file. The accessors of each part live with the part (regions.rs,
//! skin.rs, region_field.rs).

use super::build::BuildStats;
use super::core::CoreQuality;
use super::file::{Reader, Res, Writer};
use super::homogenise::Homogenisation;
use super::options::HybridOptions;
use super::transmural::VoxelGrid;
use crate::math::Vec3;
use crate::mesh::adjacency::SurfaceAdjacency;
use crate::mesh::signed_volume;

/// The compiled hybrid model: the FEM core, the particle shell, the skin and the activation
/// regions. Positions in metres, world frame of the input surfaces.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HybridModel {
    pub options: HybridOptions,
    /// Volume enclosed by the wall's boundary \[m^3\].
    pub wall_volume: f64,
    // --- FEM core (Omega_e) ---
    pub core_points: Vec<Vec3>,
    pub core_tets: Vec<[usize; 4]>,
    /// Outer boundary faces of the core (towards the shell), oriented outward: where particles
    /// and skin attach.
    pub core_faces: Vec<[usize; 3]>,
    /// Core nodes on a base (held fixed), empty for a closed wall.
    pub core_base_nodes: Vec<usize>,
    pub core_quality: CoreQuality,
    // --- particles (Omega_p), sorted by the outer triangle above them ---
    /// Lattice spacing \[m\].
    pub spacing: f64,
    pub particles: Vec<Vec3>,
    pub particle_mass: Vec<f64>,
    /// Outer triangle above each particle, core face below it.
    pub particle_outer_tri: Vec<u32>,
    pub particle_core_face: Vec<u32>,
    /// Particles of outer triangle `t`: `tri_particle_ptr[t]..tri_particle_ptr[t+1]`.
    pub tri_particle_ptr: Vec<u32>,
    // --- outer surface ---
    pub outer_points: Vec<Vec3>,
    pub outer_tris: Vec<[usize; 3]>,
    // --- activation regions, one per outer vertex ---
    /// nv(p_s) is the outer triangles within `region_rings[s]` rings of vertex `s` (1: the
    /// triangles around it). RV(p_s), C(p_s) and the core faces under RV follow from it (see
    /// [`HybridModel::region_triangles`]): one byte per region is stored.
    pub region_rings: Vec<u8>,
    /// Outer-surface adjacency (derived from `outer_tris`, not stored in the file).
    pub outer_adjacency: SurfaceAdjacency,
    /// B(p_s): voxel index box `[i0, j0, k0, i1, j1, k1)` in the shared voxel grid.
    pub region_box: Vec<[u32; 6]>,
    // --- skin ---
    /// Per outer vertex: the core face its projection hits, barycentric coordinates on it and
    /// the rest offset from that anchor point to the vertex \[m\].
    pub skin_face: Vec<u32>,
    pub skin_bary: Vec<[f64; 3]>,
    pub skin_offset: Vec<Vec3>,
    // --- shared voxels ---
    pub grid: VoxelGrid,
    /// Per voxel: the outer triangle its field line reaches, or [`super::VOXEL_OUTSIDE`] /
    /// [`super::VOXEL_CORE`].
    pub voxel_owner: Vec<u32>,
    pub stats: BuildStats,
    /// The core's homogenised stiffness (empty: not computed; see [`super::homogenise`]).
    pub homogenisation: Homogenisation,
}

impl HybridModel {
    /// Number of activation regions (one per outer-surface vertex).
    pub fn n_regions(&self) -> usize {
        self.region_box.len()
    }

    /// Total core volume \[m^3\].
    pub fn core_volume(&self) -> f64 {
        self.core_tets
            .iter()
            .map(|t| signed_volume(&self.core_points[t[0]], &self.core_points[t[1]], &self.core_points[t[2]], &self.core_points[t[3]]))
            .sum()
    }

    /// Shell volume represented by the particles (lattice cells) \[m^3\].
    pub fn shell_volume(&self) -> f64 {
        self.particles.len() as f64 * self.spacing.powi(3)
    }
}

/// The wall's section: its volume.
pub(super) fn write_wall(m: &HybridModel, w: &mut Writer) {
    w.f64(m.wall_volume);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read_wall(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.wall_volume = r.f64("wall volume")?;
    Ok(())
}
