//! The devices without hardware: [`Scripted`] (a tool trajectory: a press, a slide, a release),
//! [`Replay`] (a recorded interaction's inputs) and [`Hand`] (a mass-spring-damper following a
//! target another thread moves). The network bridge is [`crate::bridge`].

pub mod hand;
pub mod replay;
pub mod scripted;

pub use hand::{Hand, HandParams};
pub use replay::{Replay, ReplayCheck};
pub use scripted::Scripted;
