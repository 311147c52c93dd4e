//! The network bridge: a [`Bridge`] device that opens a session for one client, takes its state
//! packets over UDP and sends it the forces, and a [`Client`] (the other end, for Rust clients
//! and tests; Python's is `palpate.devices.bridge`). The wire format: [`protocol`] and
//! `PROTOCOL.md`.

pub mod protocol;
pub mod udp;

pub use protocol::Key;
pub use udp::{Bridge, BridgeError, BridgeOptions, BridgeStats, Client, ClientError, HANDOVER};
