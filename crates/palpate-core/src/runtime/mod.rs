//! The online tick of the hybrid model (paper §5-§7): reads a compiled [`Sim`], never the build
//! stages. A file per concept: `embed.rs` (points tied to core faces: skin and inactive
//! particles), `coupling.rs` (particles <-> core faces,
//! momentum-exact), `sim.rs` (the compiled simulation).

pub mod coupling;
pub mod embed;
pub mod sim;

pub use coupling::Coupling;
pub use embed::Embedding;
pub use sim::{Sim, SimOptions};
