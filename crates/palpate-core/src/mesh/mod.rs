//! Meshes: the validated tetrahedral mesh and generators of the paper's geometries.
//!
//! File formats are read in Python (meshio) and handed here as arrays; everything that can be
//! wrong with a mesh is checked here, once, in [`TetMesh::from_arrays`].

pub mod adjacency;
pub mod generate;
pub mod prism;
mod tet_mesh;

pub use tet_mesh::{boundary_faces, signed_volume, MeshWarning, TetMesh};

pub mod pieces;
pub mod sample;
pub mod simplify;
pub mod surface;

pub use pieces::{Pieces, WithoutSpecks};
pub use sample::{sample_between, sample_inside, ParticleSet};
pub use surface::{ellipsoid_surface, winding_number, SurfaceError, SurfaceWarning, TriSurface};

/// Points given as arrays, as [`crate::Vec3`]s; `Err(i)` names the first with a non-finite
/// coordinate.
fn finite_points(points: &[[f64; 3]]) -> Result<Vec<crate::Vec3>, usize> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| Some(crate::Vec3::new(p[0], p[1], p[2])).filter(crate::math::is_finite3).ok_or(i))
        .collect()
}
