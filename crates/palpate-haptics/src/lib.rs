//! palpate's haptic loop over the hybrid runtime: the threads, clocks, devices and network that
//! the core keeps out (see ARCHITECTURE.md).
//!
//! - [`servo`]: [`HapticCore`] (one deterministic tick: device sample in, force out) and
//!   [`Servo`] (the native thread at 250 Hz-4 kHz, absolute-deadline pacing, a watchdog);
//! - [`multirate`]: the servo and the physics on two threads, the servo rendering from a local
//!   model (force and stiffness at the tool) the physics publishes, never waiting for it;
//! - [`physics`]: what the servo steps ([`Physics`]): [`HybridPhysics`] (the hybrid runtime),
//!   [`FemPhysics`] (a full-FEM body), [`Wall`], [`Idle`];
//! - [`surface_contact`]: the sphere against a tet mesh's boundary triangles (a penalty per unit
//!   area, sampled), [`FemPhysics`]' contact;
//! - [`coupling`]: the virtual coupling (device <-> simulated tool), why a proxy with a mass;
//! - [`safety`]: force limit, force-rate limit, ramp;
//! - [`device`], [`devices`]: the [`Device`] interface; scripted, replay, simulated hand;
//! - [`bridge`]: the UDP bridge and its versioned binary protocol (`PROTOCOL.md`): vendor
//!   devices connect through it as separate processes;
//! - [`spec`]: a loop described as values ([`LoopSpec`]: physics, device, servo, safety) and
//!   built by one constructor that checks it;
//! - [`record`]: record and replay files; [`snapshot`]: non-blocking snapshots; [`stats`].
//!
//! Units: SI throughout (m, s, N, kg); positions and forces in the model's world frame; the force
//! sent to a device is the force on the user's hand.

pub mod bridge;
pub mod coupling;
pub mod device;
pub mod devices;
pub mod multirate;
pub mod physics;
pub mod pool;
pub mod realtime;
pub mod record;
pub mod safety;
pub mod servo;
pub mod snapshot;
pub mod spec;
pub mod stats;
/// The sphere against a tet mesh's surface, moved to the core beside the FEM body
/// ([`palpate_core::contact::surface`]); its old path kept.
pub use palpate_core::contact::surface as surface_contact;

pub use coupling::{CouplingParams, VirtualCoupling};
pub use device::{Device, DeviceInput, DeviceKind, ForceCell, ForceSink};
pub use physics::{default_area_stiffness, FemOptions, FemPhysics, HybridPhysics, Identity, Idle, Physics, Wall};
pub use pool::SpinPool;
pub use realtime::Realtime;
pub use record::{Recording, TickRecord};
pub use safety::{Safety, SafetyParams};
pub use servo::{Fault, FaultRecord, HapticCore, Servo, ServoConfig, ServoHandle, ServoReport, TickOut, IDLE_SNAPSHOT_TICKS};
pub use snapshot::{Mailbox, Snapshot, SnapshotCell, Vec3Cell};
pub use spec::{BuiltLoop, CouplingSpec, DeviceSpec, LoopError, LoopSpec, PhysicsSpec, SafetySpec};
pub use stats::Stats;
pub use surface_contact::{AreaTool, SurfaceContact};
