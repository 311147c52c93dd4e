//! Finite elements: the linear tetrahedron of paper §3.1 (eq. 12-22) and the quadratic (10-node)
//! one on the same continuum (`tet10.rs`: it bends where linear tets lock, the references' and,
//! in time, the core's element), and the FEM body built of either
//! ([`ModelBuilder::order`]): an immutable [`Model`] compiled by [`ModelBuilder`], the mutable [`State`] and the scratch
//! [`Workspace`] (MuJoCo's `mjModel` / `mjData` split), stepped by [`crate::step`]
//! (`integrate/`). A model is validated once, by [`ModelBuilder::build`]; stepping then assumes
//! validity. The particle body ([`crate::meshfree`]) has the same shape.

pub(crate) mod lanes;
pub(crate) mod model;
pub mod small_strain;
mod state;
pub mod tangent;
pub mod tet10;
pub mod tet4;
pub mod viscous;

pub use model::{ElementFields, Model, ModelBuilder};
pub use small_strain::Order;
pub use state::{State, StepMemory, Workspace};
pub use tet4::TetRest;
