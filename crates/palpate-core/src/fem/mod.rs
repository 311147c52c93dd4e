//! Finite elements: the linear tetrahedron of paper §3.1 (eq. 12-22).

pub mod tangent;
pub mod tet4;
pub mod viscous;

pub use tet4::TetRest;
