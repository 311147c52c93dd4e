//! Sparse linear algebra for the implicit integrators and the static solve.
//!
//! The systems are symmetric positive definite (`M - h D - h^2 K` and `-K` near rest), small to
//! medium (10^2 - 10^5 unknowns) and solved thousands of times per second with the same pattern,
//! so the design is: a 3x3-block pattern over the free nodes built once ([`BlockPattern`]), a
//! fill-reducing node ordering computed once ([`ordering`]), a symbolic LDL^T analysis once, and a
//! numeric factorisation and solves that allocate nothing ([`ldl`]).

pub mod block;
pub mod cg;
pub mod ldl;
pub mod ordering;
mod supernodal;

pub use block::BlockPattern;
pub use ldl::{Ldl, LdlError};
pub use supernodal::SUPERNODAL_MIN_BLOCKS;
