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
//! - [`stability`]: how many particle sub-steps a tick needs (stretch, springs, contact);
//! - [`sim`], [`state`]: the compiled simulation, its state and workspace;
//! - [`tick`]: the one ordered tick, tool in, force out.
//!
//! **Status (issue 12, in progress).** Each exchange is exact: the tick conserves linear
//! momentum to round-off with the tool away and changes it by the tool's impulse with the tool
//! (tests/runtime.rs), and an idle shell leaves the core bit-identical to the same core alone.
//! The tool meets the skin, which carries the force to the particles under it (a surface: the
//! tool cannot slip between particles), and the core's surface. The core takes the shell's
//! reactions explicitly, once a tick, so the coupling springs are capped by the core nodes'
//! masses (which carry the shell's, see [`sim`]); particles with fewer than 6 neighbours are held
//! (~2% of a lattice shell). Measured (`examples/touch.rs`, synthetic ventricle): 5, 10 and
//! 15 mm presses with a 10 mm slide run stably, 1.8-3.6 ms a tick with 630-1,100 active
//! particles. Not yet: the closed ellipsoid diverges after a 3-4 mm press (the organ, held at
//! its lower part, tilts away and the ties' unrotated offsets distort the shell); the tick is
//! 4-7x over its 0.5 ms target; the active sets exceed 600; nothing is exposed to Python.

pub mod activation;
pub mod confinement;
pub mod coupling;
pub mod embed;
pub mod sim;
pub mod stability;
pub mod state;
pub mod tick;
pub mod tool;

pub use activation::{ActiveSets, Activation};
pub use confinement::{Confinement, ConfinementSum, Placement, Push};
pub use coupling::Coupling;
pub use embed::Embedding;
pub use sim::{Sim, SimOptions};
pub use stability::Shell;
pub use state::{SimState, SimWorkspace};
pub use tick::{tick, TickReport};
pub use tool::{ContactSum, PointContact, Tool};
