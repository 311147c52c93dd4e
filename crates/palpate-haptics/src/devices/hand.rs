//! A simulated hand: a point mass on a spring-damper to a target that another thread sets (the
//! viewer drags it), pushed back by the force the servo renders. What a user's hand does to a
//! device, to first order: it follows an intent through a compliant arm.

use std::sync::Arc;

use palpate_core::Vec3;

use crate::device::{Device, DeviceInput, DeviceKind, ForceCell, ForceSink};
use crate::snapshot::Vec3Cell;

/// The hand's parameters (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandParams {
    /// The hand and handle's mass \[kg\] (default 0.1 kg: a fingertip grip on a stylus).
    pub mass: f64,
    /// The arm's stiffness toward the target \[N/m\] (default 200 N/m).
    pub stiffness: f64,
    /// The arm's damping \[N s/m\] (default 8 N s/m, about critical `2 sqrt(k m) = 8.9`).
    pub damping: f64,
}

impl Default for HandParams {
    fn default() -> Self {
        HandParams { mass: 0.1, stiffness: 200.0, damping: 8.0 }
    }
}

/// The simulated hand (see the module).
pub struct Hand {
    pub params: HandParams,
    target: Arc<Vec3Cell>,
    sink: Arc<ForceCell>,
    x: Vec3,
    v: Vec3,
}

impl Hand {
    /// A hand at rest at `at` \[m\], its target there too.
    pub fn new(params: HandParams, at: Vec3) -> Hand {
        Hand { params, target: Arc::new(Vec3Cell::new(at)), sink: Arc::new(ForceCell::default()), x: at, v: Vec3::zeros() }
    }
    /// The target cell: another thread sets it (`target().set(&p)`), never blocking the servo.
    pub fn target(&self) -> Arc<Vec3Cell> {
        self.target.clone()
    }
    pub fn forces(&self) -> Arc<ForceCell> {
        self.sink.clone()
    }
}

impl Device for Hand {
    fn read(&mut self, _tick: u64, dt: f64) -> Option<DeviceInput> {
        let HandParams { mass: m, stiffness: k, damping: c } = self.params;
        let target = self.target.get();
        let f = self.sink.get();
        // Semi-implicit in the arm's spring and damper (stable at any rate), the rendered force
        // explicit (from the last tick, as a real hand feels it).
        let rhs = self.v * (m / dt) + (target - self.x) * k + f;
        let target_ok = target.iter().all(|c| c.is_finite()) && f.iter().all(|c| c.is_finite());
        if target_ok {
            self.v = rhs / (m / dt + k * dt + c);
            self.x += self.v * dt;
        }
        Some(DeviceInput::at(self.x))
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
}
