//! The rigid sphere tool against a body: the contact laws every body shares (`tool.rs`: the
//! penalty of a point, per unit of area, its damping and stability bounds), and the sphere
//! against a tet mesh's boundary surface sampled over its triangles (`surface.rs`, the FEM
//! body's contact in the haptic loop). Physics only: the loops that tick them live in
//! `palpate-haptics`, the hybrid's own contact stages in [`crate::runtime`].

pub mod surface;
pub mod tool;

pub use surface::SurfaceContact;
pub use tool::{AreaTool, ContactSum, PointContact, Tool, ToolOptions};
