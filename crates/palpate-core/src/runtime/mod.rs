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
//! - [`core_contact`]: the tool against what moves with the core (the skin no particle carries,
//!   the core's surface) inside the core's implicit step;
//! - [`coupling`]: damped springs between the first-layer active particles and their core faces,
//!   momentum-exact (where and why this departs from the paper: see the module);
//! - [`stability`]: how many particle sub-steps a tick needs (stretch, springs, contact);
//! - [`skin`]: the outer surface the tool meets and the user sees: its update (the tick's last
//!   stage), the sub-steps' view of it near the tool, and a shed shell's skin fading back;
//! - [`sim`], [`state`]: the compiled simulation, its state and workspace, and the state as
//!   plain values to save and restore ([`SimSnapshot`]);
//! - [`tick`](mod@tick): the one ordered tick, tool in, force out, orchestrating its stages (a
//!   file each under `tick/`: activation and the ring, the shell's sub-steps with shedding, the
//!   core's contact and step); [`tick_with`] the same with the particle passes split over a
//!   caller's threads ([`crate::parallel`]), bitwise equal.
//!
//! **Status (issue 12).** Each exchange is exact: the tick conserves linear momentum to
//! round-off with the tool away and changes it by the tool's impulse with the tool
//! (tests/runtime.rs), and an idle shell leaves the core bit-identical to the same core alone.
//! The tool meets the skin, which carries the force to the particles under it (a surface: the
//! tool cannot slip between particles), and the core's surface. Stability under a hand's worst
//! (tests/runtime_hand.rs, `bench/hybrid_hand.py`) rests on four things: the shell's sub-step
//! count from its current stretch, springs and contact ([`stability`]); ties whose offsets turn
//! with their faces ([`embed`]); held (lone) particles carried by their ties every tick; and a
//! compression barrier in the particle law (`crate::meshfree::COMPRESSION_FLOOR`); where they do
//! not suffice (a press beside a held base, see [`stability`]) the tick sheds the failed shell and
//! goes on with the core and the skin ([`SimOptions::shell_fallback`]). Measured (2026-11-27):
//! 15 mm presses, a press toward 5 N over up to 25 mm of travel, a 0.5 m/s slide, a 5 mm jump
//! after a stall and a 10 mm jab stay finite with the shell kept on the synthetic ventricle, the
//! paper's ellipsoids and the Rodero ventricle; a press toward 2 N at 24 points of the synthetic
//! ventricle sheds the shell at 9 of them (14 undamped), from 7-20 mm of travel, with the force
//! changing by at most 0.13 N a tick there; a slow slide over 50 region changes moves the force
//! by at most 20% of the 0.01 N allowance per tick. The shell's selective mass scaling
//! (`crate::meshfree` `mass_scaling.rs`) takes 40% of the sub-steps off the Rodero ventricle's
//! and 30% off the ellipsoids' ticks. The whole tick is over issue 12's mean targets (0.25 ms at
//! 200 active particles, 0.5 ms at 600): the shell's explicit sub-steps alone fill them
//! (docs/history/benchmarks-log.md#twelfth-session-2026-11-27-the-shells-sub-steps-alone-fill-the-mean-targets-issue-12s-speed-targets-reported-as-blocked-here;
//! [`stability`] for why their count is what it is), while the
//! part of the tick the force waits for holds a 1 kHz servo at 600 ([`tick_force_with`]).

pub mod activation;
pub mod confinement;
pub mod core_contact;
pub mod coupling;
pub mod embed;
pub(crate) mod exchange;
pub(crate) mod homogenised_core;
pub mod scale;
pub mod sim;
pub mod skin;
pub mod stability;
pub mod state;
pub mod tick;
/// The tool's contact laws live in [`crate::contact::tool`] (every body's); re-exported here, where
/// the hybrid runtime uses them.
pub use crate::contact::tool;

pub use activation::{Activation, ActiveSets};
pub use confinement::{Confinement, ConfinementSum, Placement, Push};
pub use core_contact::{CoreContact, CoreContactSum};
pub use coupling::Coupling;
pub use embed::Embedding;
pub use sim::{Sim, SimOptions};
pub use skin::SHED_FADE;
pub use stability::Shell;
pub use state::{SimSnapshot, SimState, SimWorkspace, SkinSweep};
pub use tick::{finish_tick, tick, tick_force_with, tick_with, Finished, TickReport};
pub use tool::{AreaTool, ContactSum, PointContact, Tool, ToolOptions};
