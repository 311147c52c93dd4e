//! Devices behind one interface ([`Device`]): what the servo reads each tick (a position, an
//! orientation, buttons) and where it sends the force ([`ForceSink`]).
//!
//! Frames and units: positions in metres in the model's world frame, forces in newtons on the
//! user's hand in the same frame. A device whose native frame differs (a vendor device's
//! millimetres and its own axes) is mapped before it reaches the servo: by its bridge client
//! (`palpate device ...`, see the bridge protocol) or by its [`Device`] implementation.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use palpate_core::Vec3;

use crate::coupling::CouplingParams;
use crate::safety::SafetyParams;
use crate::snapshot::SeqLock;

/// One sample of a device (world frame, SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceInput {
    /// The handle's position \[m\].
    pub position: Vec3,
    /// The handle's orientation, a unit quaternion `[w, x, y, z]` (identity if the device has
    /// none). Carried and recorded; the spherical tool does not use it.
    pub orientation: [f64; 4],
    /// Buttons, bit `i` for button `i`.
    pub buttons: u32,
}

impl DeviceInput {
    pub fn at(position: Vec3) -> DeviceInput {
        DeviceInput { position, orientation: [1.0, 0.0, 0.0, 0.0], buttons: 0 }
    }
    /// All numbers finite?
    pub fn is_finite(&self) -> bool {
        self.position.iter().all(|c| c.is_finite()) && self.orientation.iter().all(|c| c.is_finite())
    }
}

/// Where forces go. `send` takes `&self` so that the watchdog (another thread) can zero the
/// force while the servo thread is stuck in a physics tick.
pub trait ForceSink: Send + Sync {
    /// Sends `force` \[N\] (world frame, on the user's hand). Never blocks.
    fn send(&self, force: &Vec3);
    /// Sends zero force because of a fault or the watchdog (a bridge flags it).
    fn zeroed(&self) {
        self.send(&Vec3::zeros())
    }
}

/// The last force sent, readable from any thread (a seqlock), and how many were sent: the sink
/// of the simulated devices.
#[derive(Debug, Default)]
pub struct ForceCell {
    force: SeqLock<3>,
    sent: AtomicU64,
}

impl ForceCell {
    pub fn get(&self) -> Vec3 {
        let (w, _) = self.force.read();
        Vec3::new(f64::from_bits(w[0]), f64::from_bits(w[1]), f64::from_bits(w[2]))
    }
    pub fn sent(&self) -> u64 {
        self.sent.load(Ordering::Relaxed)
    }
}

impl ForceSink for ForceCell {
    fn send(&self, f: &Vec3) {
        // Two writers may race (servo and watchdog): each write is whole (the seqlock's sequence
        // then only orders them), which is all a "last force" cell needs.
        self.force.write(&[f.x.to_bits(), f.y.to_bits(), f.z.to_bits()]);
        self.sent.fetch_add(1, Ordering::Relaxed);
    }
}

/// The device classes, each with safe defaults for the coupling and the safety layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    /// Scripted, replayed or simulated-hand devices (no hardware).
    Simulated,
    /// A bridge client of unknown make.
    Bridge,
    /// 3D Systems (Geomagic) Touch: 3.3 N peak, ~1 N/mm nominal stiffness.
    Touch,
    /// Force Dimension omega / Novint Falcon: ~9-12 N peak.
    ForceDimension,
    /// Haply Inverse3.
    Haply,
    /// Moog FCS HapticMaster (the paper's): 250 N peak, admittance-controlled.
    HapticMaster,
}

impl DeviceKind {
    /// The coupling's and the safety layer's defaults for this device. The force limit is the
    /// issue's 3 N for all (the Touch's peak is 3.3 N); the coupling's stiffness is about a
    /// third of what the device renders stably (Adams and Hannaford: the coupling, not the
    /// contact, bounds the rendered impedance), its damping near the proxy's critical.
    pub fn defaults(self) -> (CouplingParams, SafetyParams) {
        let c = match self {
            DeviceKind::Simulated | DeviceKind::Bridge => CouplingParams::default(),
            DeviceKind::Touch => CouplingParams::new(300.0, 1.0, 0.01),
            DeviceKind::ForceDimension => CouplingParams::new(500.0, 2.0, 0.01),
            DeviceKind::Haply => CouplingParams::new(500.0, 2.0, 0.01),
            DeviceKind::HapticMaster => CouplingParams::new(2000.0, 5.0, 0.02),
        };
        (c, SafetyParams::default())
    }

    /// What the class is rated for: the force limit and the coupling's stiffness beyond these
    /// are refused ([`crate::safety::check_limits`]) unless the user asks for unsafe limits.
    /// The makers' figures: Touch 3.3 N peak, 1.02-2.31 N/mm by axis (the least); Force
    /// Dimension omega.3 12 N, 14.5 N/mm (a Falcon saturates at its own ~8 N); Moog FCS
    /// HapticMaster 250 N, 50 N/mm. The Haply Inverse3's and an unknown bridge client's are
    /// taken as the Touch's (the most cautious of the classes) until checked; simulated devices
    /// push no hand, and are bounded as CHAI3D's virtual device (10 N) with the Falcon's 3 N/mm.
    pub fn rated(self) -> Rated {
        let (max_force, max_stiffness) = match self {
            DeviceKind::Simulated => (10.0, 3000.0),
            DeviceKind::Bridge | DeviceKind::Touch | DeviceKind::Haply => (3.3, 1020.0),
            DeviceKind::ForceDimension => (12.0, 14_500.0),
            DeviceKind::HapticMaster => (250.0, 50_000.0),
        };
        Rated { max_force, max_stiffness }
    }

    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Simulated => "simulated",
            DeviceKind::Bridge => "bridge",
            DeviceKind::Touch => "geomagic",
            DeviceKind::ForceDimension => "forcedimension",
            DeviceKind::Haply => "haply",
            DeviceKind::HapticMaster => "hapticmaster",
        }
    }
}

/// A device class's rated figures (SI units; see [`DeviceKind::rated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rated {
    /// The largest force the device exerts \[N\].
    pub max_force: f64,
    /// The largest stiffness it renders stably \[N/m\].
    pub max_stiffness: f64,
}

/// A haptic device as the servo sees it. `read` and the sink's `send` never block (a device
/// whose sample has not arrived returns `None`: the servo holds the last one).
pub trait Device: Send {
    /// The sample for tick `tick` (0-based; the tick lasts `dt` \[s\]), or `None` (no new one).
    fn read(&mut self, tick: u64, dt: f64) -> Option<DeviceInput>;
    /// Where the forces go (shared with the watchdog).
    fn sink(&self) -> Arc<dyn ForceSink>;
    fn kind(&self) -> DeviceKind;
    /// A finite device (a script, a recording) that has nothing more to give after `ticks`
    /// ticks of `dt` \[s\].
    fn finished(&self, _ticks: u64, _dt: f64) -> bool {
        false
    }
}
