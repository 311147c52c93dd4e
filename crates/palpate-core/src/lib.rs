//! # palpate-core
//!
//! The physics of palpate, a real-time soft-tissue simulator for haptic interaction, after
//! M. G. Mero and A. Susin, *Deformable Hybrid Approach for Haptic Interaction* (the "paper").
//!
//! Units are SI throughout: positions in metres \[m\], forces in newtons \[N\], time in seconds \[s\],
//! moduli in pascals \[Pa\], densities in \[kg/m^3\], viscosities in \[Pa s\]. Arrays of points are
//! `(n_nodes)` slices of [`Vec3`] in the world frame.
//!
//! The data flow follows MuJoCo's split of `mjModel` and `mjData`:
//!
//! ```text
//! TetMesh (validated) + Material + fixed nodes ──ModelBuilder::build──▶ Model (immutable)
//!                                                                       │
//!                         State (x, v, t, f_ext) ◀── State::rest ───────┤
//!                         Workspace (scratch, factorisations) ◀─────────┘
//!      step(&Model, &mut State, &mut Workspace, dt) -> Result<StepReport, StepError>
//! ```
// No unsafe code, except in three audited places: the AVX2 + FMA copy of the particle hot loop
// (`meshfree/pair_loop/avx2.rs`), which needs `unsafe` to call a `target_feature` function after
// run-time detection and skips bounds checks on neighbour indices validated at compile time; the
// one call into the AVX2 + FMA copy of the FEM's element loop (`fem/lanes.rs`), after the same
// detection; and the particle passes split over a caller's threads (`parallel.rs`: `Fork` is an
// `unsafe trait`, each part run exactly once; `meshfree/pair_loop/disjoint.rs`: the parts write
// disjoint particles of one array, which the active list allows when `touch` finds no repeat).
#![deny(unsafe_code)]
// `!(x > 0.0)` is how this crate rejects NaN together with the out-of-range values (a NaN fails
// every comparison); clippy's `partial_cmp` rewrite would hide exactly that.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Element and block math indexes several small arrays with the same node / component index
// (`f[a]`, `cof[a][b]`); iterator zips of three or four of them read worse than the formulas.
#![allow(clippy::needless_range_loop)]

pub mod contact;
pub mod divergence;
pub mod error;
pub mod fem;
pub mod hybrid;
pub mod integrate;
pub mod limits;
pub mod linalg;
pub mod material;
pub mod math;
pub mod mesh;
pub mod meshfree;
pub mod parallel;
pub mod probe;
pub mod runtime;
pub mod spatial;

pub use error::{HybridError, LimitError, LoadError, MaterialError, MeshError, ModelError, ModelFileError, SolveError, StepError};
pub use fem::{Model, ModelBuilder, Order, State, StepMemory, Workspace};
pub use integrate::{step, Integrator, StepReport};
pub use material::{Law, Material};
pub use math::{Mat3, Real, Vec3};
pub use mesh::TetMesh;
