//! The online tick of the hybrid model (paper §5-§7, issue 12): reads a
//! [`HybridModel`](crate::hybrid::HybridModel), never writes it, and never calls the build
//! stages.
//!
//! The parts here are self-contained (pure functions and small structs over slices, each
//! allocation-free per tick), for the one ordered tick to compose:
//! - [`tool`]: the rigid sphere tool and its penalty contact (why penalty: see the module);
//! - [`activation`]: the active particles as the union of the touched regions RV(p_s), with
//!   hysteresis, and the particles that entered and left;
//! - [`confinement`]: the elastic wall that keeps the active particles inside the union of their
//!   regions (the paper's B(p_s) gradient field, computed locally).

pub mod activation;
pub mod confinement;
pub mod tool;

pub use activation::{ActiveSets, Activation};
pub use confinement::{Confinement, ConfinementSum, Placement, Push};
pub use tool::{ContactSum, PointContact, Tool};
