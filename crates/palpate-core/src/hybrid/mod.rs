//! The hybrid model of the paper (§4, §6): a coarse FEM core (Omega_e) against the inner surface
//! of an organ wall, a shell of meshfree particles (Omega_p) up to the outer surface, the skin
//! (each outer vertex tied to a core face) and one activation region per outer vertex.
//!
//! [`build`] compiles a [`HybridModel`] from a [`Wall`] (two nested closed surfaces, or one
//! closed surface tagged inner / outer / base); [`file`] saves and loads it.

pub mod build;
pub mod file;
pub mod geometry;
pub mod shapes;
pub mod transmural;

pub use build::{build, BuildStats, CoreQuality, HybridModel, HybridOptions, RegionField, Spacing, VoxelLabel, Wall, VOXEL_CORE, VOXEL_OUTSIDE};
pub use transmural::{Projection, VoxelGrid, WallPart};
