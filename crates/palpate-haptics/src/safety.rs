//! The safety layer between the coupling and the device: a force limit, a force-rate limit and a
//! ramp-up on start (and after every fault). The watchdog (missed ticks, non-finite state) lives
//! in the servo ([`crate::servo`]), which zeroes the force through [`Safety::zero`].
//!
//! Order within a tick: ramp (scales the coupling's force by `min(1, ticks / ramp_ticks)`), then
//! the magnitude limit (direction kept), then the rate limit (the change from the last output is
//! at most `max_rate dt` in magnitude). The rate limit last, so that no step of the output ever
//! exceeds it, except a fault's drop to zero, which is immediate by design (the watchdog must
//! zero the force within one tick).

use palpate_core::Vec3;

use crate::coupling::CouplingParams;
use crate::device::DeviceKind;

/// Safety parameters (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyParams {
    /// The largest force magnitude sent to the device \[N\] (default 3 N: below the continuous
    /// force of the desktop devices, see [`crate::DeviceKind`]).
    pub max_force: f64,
    /// The largest change of the force per second \[N/s\] (default 1,000 N/s: a 2 N contact
    /// onset takes 2 ms, which a hand does not feel as a delay, while a jump cannot kick).
    pub max_rate: f64,
    /// The ramp-up from zero to full force on start and after a fault \[s\] (default 0.5 s).
    pub ramp: f64,
    /// Physics that misses ticks for this long \[s\] trips the watchdog (default 30 ms).
    pub stall_timeout: f64,
    /// No new device sample for this long \[s\] fades the force to zero over the next
    /// [`crate::multirate::SILENCE_FADE`] (30 ms), logged; the device's return ramps the force
    /// up again (default 50 ms).
    pub silence: f64,
}

impl Default for SafetyParams {
    fn default() -> Self {
        SafetyParams { max_force: 3.0, max_rate: 1000.0, ramp: 0.5, stall_timeout: 0.030, silence: 0.050 }
    }
}

impl SafetyParams {
    pub fn check(&self) -> Result<(), String> {
        let pos = |v: f64| v > 0.0 && v.is_finite();
        if !pos(self.max_force) {
            return Err(format!("max_force = {} N must be positive and finite", self.max_force));
        }
        if !pos(self.max_rate) {
            return Err(format!("max_rate = {} N/s must be positive and finite", self.max_rate));
        }
        if !(self.ramp >= 0.0 && self.ramp.is_finite()) {
            return Err(format!("ramp = {} s must be non-negative and finite", self.ramp));
        }
        if !pos(self.stall_timeout) {
            return Err(format!("stall_timeout = {} s must be positive and finite", self.stall_timeout));
        }
        if !pos(self.silence) {
            return Err(format!("silence = {} s must be positive and finite", self.silence));
        }
        Ok(())
    }
}

/// The longest a watchdog or a silence timeout may be \[s\]: a hand pushed by a stalled
/// simulation, or by a device that stopped reporting, for longer than this is a hand the loop
/// no longer controls.
pub const MAX_TIMEOUT: f64 = 0.100;

/// The limits a device class may run with: a force limit at most the class's rated force, a
/// coupling at most its rated stiffness, watchdog and silence timeouts at most
/// [`MAX_TIMEOUT`]. Beyond them, an error that says what and why; the caller may let the user
/// override it explicitly (`unsafe_limits`), and logs that it did.
pub fn check_limits(kind: DeviceKind, coupling: &CouplingParams, safety: &SafetyParams) -> Result<(), String> {
    let r = kind.rated();
    let name = kind.name();
    if safety.max_force > r.max_force {
        return Err(format!("max_force = {} N is above the {name} device class's rated {} N", safety.max_force, r.max_force));
    }
    if coupling.stiffness > r.max_stiffness {
        return Err(format!("coupling stiffness = {} N/m is above the {name} device class's rated {} N/m", coupling.stiffness, r.max_stiffness));
    }
    if safety.stall_timeout > MAX_TIMEOUT {
        return Err(format!(
            "stall_timeout = {} s is above {} s: the watchdog would let a stalled simulation push the hand that long",
            safety.stall_timeout, MAX_TIMEOUT
        ));
    }
    if safety.silence > MAX_TIMEOUT {
        return Err(format!("silence = {} s is above {} s: a silent device would be pushed that long", safety.silence, MAX_TIMEOUT));
    }
    Ok(())
}

/// The safety layer's state: the last force sent, the ticks since the last (re)start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Safety {
    pub params: SafetyParams,
    last: Vec3,
    since_start: u64,
}

impl Safety {
    pub fn new(params: SafetyParams) -> Safety {
        Safety { params, last: Vec3::zeros(), since_start: 0 }
    }

    /// The force to send \[N\] for the coupling's `force` at tick length `dt` \[s\]. A non-finite
    /// `force` gives zero (the servo reports it as a fault).
    pub fn apply(&mut self, force: &Vec3, dt: f64) -> Vec3 {
        if !force.iter().all(|c| c.is_finite()) {
            return self.zero();
        }
        self.since_start += 1;
        let ramp_ticks = (self.params.ramp / dt).ceil();
        let scale = if ramp_ticks <= 0.0 { 1.0 } else { (self.since_start as f64 / ramp_ticks).min(1.0) };
        let f = (force * scale).cap_magnitude(self.params.max_force);
        let out = self.last + (f - self.last).cap_magnitude(self.params.max_rate * dt);
        self.last = out;
        out
    }

    /// Zero force now, and the ramp starts again.
    pub fn zero(&mut self) -> Vec3 {
        self.last = Vec3::zeros();
        self.since_start = 0;
        self.last
    }

    /// The last force sent \[N\].
    pub fn last(&self) -> Vec3 {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limit_rate_and_ramp_hold() {
        let p = SafetyParams { max_force: 3.0, max_rate: 1000.0, ramp: 0.1, stall_timeout: 0.03, silence: 0.05 };
        let mut s = Safety::new(p);
        let dt = 1e-3;
        let big = Vec3::new(10.0, -20.0, 5.0);
        let mut prev = Vec3::zeros();
        for k in 1..=400u64 {
            let f = s.apply(&big, dt);
            assert!(f.norm() <= 3.0 + 1e-12, "limit: {}", f.norm());
            assert!((f - prev).norm() <= 1000.0 * dt + 1e-12, "rate");
            // ramp: at most k / 100 of the requested force
            assert!(f.norm() <= big.norm() * k as f64 / 100.0 + 1e-12, "ramp at tick {k}");
            prev = f;
        }
        assert!((prev.norm() - 3.0).abs() < 1e-12, "settles at the limit, along the request");
        assert!((prev.normalize() - big.normalize()).norm() < 1e-12);
        assert_eq!(s.apply(&Vec3::new(f64::NAN, 0.0, 0.0), dt), Vec3::zeros());
        // after a fault the ramp starts again
        assert!(s.apply(&big, dt).norm() <= big.norm() / 100.0 + 1e-12);
    }

    /// The rated bounds refuse what the hostile run passed (a 50 N limit with a Touch,
    /// a 100 s watchdog) and accept every class's defaults.
    #[test]
    fn limits_beyond_the_rating_are_refused() {
        for kind in [
            DeviceKind::Simulated,
            DeviceKind::Bridge,
            DeviceKind::Touch,
            DeviceKind::ForceDimension,
            DeviceKind::Haply,
            DeviceKind::HapticMaster,
        ] {
            let (c, s) = kind.defaults();
            assert_eq!(check_limits(kind, &c, &s), Ok(()), "{kind:?}");
        }
        let (c, s) = DeviceKind::Touch.defaults();
        let e = check_limits(DeviceKind::Touch, &c, &SafetyParams { max_force: 50.0, ..s }).unwrap_err();
        assert!(e.contains("max_force = 50 N") && e.contains("3.3 N"), "{e}");
        assert!(check_limits(DeviceKind::Touch, &CouplingParams { stiffness: 5000.0, ..c }, &s).unwrap_err().contains("5000 N/m"));
        assert!(check_limits(DeviceKind::HapticMaster, &c, &SafetyParams { stall_timeout: 100.0, ..s })
            .unwrap_err()
            .contains("stall_timeout"));
        assert!(check_limits(DeviceKind::Simulated, &c, &SafetyParams { silence: 0.2, ..s }).unwrap_err().contains("silence"));
        assert_eq!(check_limits(DeviceKind::HapticMaster, &c, &SafetyParams { max_force: 50.0, ..s }), Ok(()));
    }
}
