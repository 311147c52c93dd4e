//! The hybrid model of the paper (§4, §6): a coarse FEM core (Omega_e) against the inner surface
//! of an organ wall, a shell of meshfree particles (Omega_p) up to the outer surface, the skin
//! (each outer vertex tied to a core face) and one activation region per outer vertex.
//!
//! [`build()`] compiles a [`HybridModel`] from a [`Wall`] (two nested closed surfaces, or one
//! closed surface tagged inner / outer / base); [`file`](mod@file) saves and loads it. One module per part
//! of the model, each building its part and writing, reading and checking its section of the
//! model file: [`options`], `core`, `shell`, `outer`, `regions`, `region_field` (the shared
//! voxels and B(p_s)), `skin`; `model` holds the compiled model and [`build()`] the order of the
//! stages.

pub mod build;
mod core;
pub mod file;
pub mod homogenise;
mod model;
pub mod options;
mod order;
mod outer;
mod region_field;
mod regions;
pub mod shapes;
mod shell;
mod skin;
pub mod transmural;
mod wall;

pub use self::core::CoreQuality;
pub use build::{build, BuildStats};
pub use homogenise::Homogenisation;
pub use model::HybridModel;
pub use options::{HybridOptions, Spacing};
pub use region_field::{RegionField, VoxelLabel, VOXEL_CORE, VOXEL_OUTSIDE};
pub use transmural::{Projection, VoxelGrid, WallPart};
pub use wall::{Wall, MIN_PIECE_VOLUME};
