//! The compiled scene: an immutable [`Model`], the mutable [`State`] and the scratch [`Workspace`]
//! (MuJoCo's `mjModel` / `mjData` split). A model is validated once, by [`ModelBuilder::build`];
//! stepping then assumes validity.

pub(crate) mod model;
mod state;

pub use model::{Model, ModelBuilder};
pub use state::{State, Workspace};
