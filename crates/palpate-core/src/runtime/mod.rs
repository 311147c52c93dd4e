//! The online tick of the hybrid model (paper §5-§7, issue 12): reads a compiled [`Sim`] (from a
//! [`HybridModel`](crate::hybrid::HybridModel)), never writes it, and never calls the build
//! stages. A file per concept, each part allocation-free per tick:
//! - [`embed`]: points tied to core faces (the skin and the inactive particles) and the
//!   transpose that carries forces on them to the core nodes;
//! - [`tool`]: the rigid sphere tool and its penalty contact (why penalty: see the module);
//! - [`activation`]: the active particles as the union of the touched regions RV(p_s), with
//!   hysteresis, and the particles that entered and left;
//! - [`confinement`]: the elastic wall that keeps the active particles inside the union of their
//!   regions (the paper's B(p_s) gradient field, computed locally);
//! - [`coupling`]: damped springs between the first-layer active particles and their core faces,
//!   momentum-exact (where and why this departs from the paper: see the module);
//! - [`sim`], [`state`]: the compiled simulation, its state and workspace;
//! - [`tick`]: the one ordered tick, tool in, force out.

pub mod activation;
pub mod confinement;
pub mod coupling;
pub mod embed;
pub mod sim;
pub mod tool;

pub use activation::{ActiveSets, Activation};
pub use confinement::{Confinement, ConfinementSum, Placement, Push};
pub use coupling::Coupling;
pub use embed::Embedding;
pub use sim::{Sim, SimOptions};
pub use tool::{ContactSum, PointContact, Tool};
