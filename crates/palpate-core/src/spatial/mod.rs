//! Spatial indexing shared by the mesh tools, the particle builder and the hybrid builder: one
//! home for the uniform grid's index math ([`Grid3`]), one for counting-sort bucket tables
//! ([`Buckets`]), and the two bucket grids the hybrid builder queries (nearest triangle,
//! containing tet).

pub mod csr;
pub mod grid3;
pub mod morton;
pub mod tet_grid;
pub mod triangle_grid;

pub use csr::Buckets;
pub use grid3::Grid3;
pub use tet_grid::TetGrid;
pub use triangle_grid::{closest_on_triangle, Nearest, TriangleGrid};
