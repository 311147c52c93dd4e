//! The virtual coupling (Colgate, Stanley and Brown 1995; Adams and Hannaford 1999): a
//! spring-damper between the device's position and the simulated tool, so that what the device
//! renders is bounded by the coupling's stiffness, whatever the stiffness of the contact behind
//! it.
//!
//! # Which coupling, and why
//! The runtime's tool is driven by position ([`crate::Physics::tick`]), so the simulated tool is
//! a **proxy** with a small mass `m`: it is moved by the tissue's force on it and by the coupling,
//! and its position is what the simulation is given:
//! ```text
//! m a_p = F_tissue(x_p) + k (x_d - x_p) + b (v_d - v_p)          (proxy)
//! F_device = k (x_p - x_d) + b (v_p - v_d)                          (rendered on the user)
//! ```
//! The coupling terms are integrated implicitly (backward Euler in `x_p`, `v_p`), the tissue's
//! force explicitly (it comes from the simulation's last tick): the coupling spring is then
//! unconditionally stable at any `k` and rate, and the explicit part is stable while the
//! tissue's stiffness stays below `~4 (m + b dt + k dt^2) / dt^2` (1 kHz: ~49,000 N/m with the
//! defaults, far above soft tissue's few hundred). At rest in contact, `F_device = F_tissue`:
//! the user feels the tissue.
//!
//! The alternative, the device position given to the simulation directly and its force sent
//! back, renders the contact's stiffness (penalty `k` times the points in contact, thousands of
//! N/m) at the device's rate: a stiff contact is then active (Colgate: passive only if the
//! device's own damping exceeds `K T / 2`), and the device buzzes. The coupling caps `K` at `k`.
//!
//! The proxy's speed is capped at the simulated tool's top speed (the runtime's
//! `max_tool_speed`), so proxy and simulated tool are one point; a device faster than that feels
//! the coupling stretch (a drag) rather than the simulation jump.

use palpate_core::{Mat3, Vec3};

/// Coupling parameters (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingParams {
    /// Spring \[N/m\] between device and proxy: the stiffest the device is asked to render.
    pub stiffness: f64,
    /// Damper \[N s/m\] on the device-proxy relative velocity.
    pub damping: f64,
    /// The proxy's mass \[kg\].
    pub proxy_mass: f64,
}

impl CouplingParams {
    /// Safe defaults for a device class (see [`crate::DeviceKind`]): a stiffness the device can
    /// render passively at 1 kHz and a damping near critical for the proxy.
    pub const fn new(stiffness: f64, damping: f64, proxy_mass: f64) -> CouplingParams {
        CouplingParams { stiffness, damping, proxy_mass }
    }

    /// Positive and finite stiffness and mass, non-negative finite damping.
    pub fn check(&self) -> Result<(), String> {
        let ok = |v: f64, zero: bool| v.is_finite() && (v > 0.0 || (zero && v == 0.0));
        if !ok(self.stiffness, false) {
            return Err(format!("coupling stiffness = {} N/m must be positive and finite", self.stiffness));
        }
        if !ok(self.damping, true) {
            return Err(format!("coupling damping = {} N s/m must be non-negative and finite", self.damping));
        }
        if !ok(self.proxy_mass, false) {
            return Err(format!("proxy mass = {} kg must be positive and finite", self.proxy_mass));
        }
        Ok(())
    }
}

impl Default for CouplingParams {
    /// 300 N/m, 2 N s/m, 10 g: below a desktop device's ~1,000 N/m peak (Touch: ~1.0 N/mm
    /// nominal), the proxy near critical damping (`2 sqrt(k m) = 3.5` N s/m).
    fn default() -> Self {
        CouplingParams::new(300.0, 2.0, 0.01)
    }
}

/// The coupling's state: the proxy's position and velocity, the device's previous position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VirtualCoupling {
    pub params: CouplingParams,
    /// The proxy (the simulated tool) \[m\], \[m/s\].
    pub proxy: Vec3,
    pub proxy_v: Vec3,
    /// The device at the last tick \[m\] (`None` before the first: its velocity is then zero).
    device: Option<Vec3>,
}

/// One tick's output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CouplingOut {
    /// The force to render on the user \[N\].
    pub force: Vec3,
    /// The device's velocity (backward difference) \[m/s\].
    pub device_v: Vec3,
}

impl VirtualCoupling {
    /// The proxy at `at`, at rest.
    pub fn new(params: CouplingParams, at: Vec3) -> VirtualCoupling {
        VirtualCoupling { params, proxy: at, proxy_v: Vec3::zeros(), device: None }
    }

    /// Puts the proxy at `at`, at rest, and forgets the device's velocity (after a restore).
    pub fn reset(&mut self, at: Vec3) {
        self.proxy = at;
        self.proxy_v = Vec3::zeros();
        self.device = None;
    }

    /// Advances the proxy by `dt` \[s\] under the tissue's force `tissue` \[N\] (on the proxy at its
    /// current position) and the coupling to the device at `device` \[m\]; the proxy's speed is
    /// capped at `max_speed` \[m/s\]. Returns the force to render.
    pub fn step(&mut self, device: &Vec3, tissue: &Vec3, dt: f64, max_speed: f64) -> CouplingOut {
        self.advance(device, tissue, None, dt, max_speed)
    }

    /// The proxy's implicit step (both loops): the tissue's force `tissue` at the proxy's
    /// current position, with `stiffness` (`K` times its weight) taken at its new one when
    /// there is one, the coupling's spring and damper at the new velocity:
    /// `(m/dt + b + k dt) v' + K dt v' = (m/dt) v + F_t + k (x_d - x) + b v_d`.
    fn advance(&mut self, device: &Vec3, tissue: &Vec3, stiffness: Option<Mat3>, dt: f64, max_speed: f64) -> CouplingOut {
        let CouplingParams { stiffness: k, damping: b, proxy_mass: m } = self.params;
        let device_v = self.device.map_or(Vec3::zeros(), |p| (device - p) / dt);
        self.device = Some(*device);
        let rhs = self.proxy_v * (m / dt) + tissue + (device - self.proxy) * k + device_v * b;
        let diagonal = m / dt + k * dt + b;
        // With a stiffness the matrix is symmetric positive definite (K is projected to PSD
        // where it is made): Cholesky cannot fail for finite input; a non-finite model leaves
        // the proxy's velocity as the coupling alone would set it.
        let mut v = match stiffness.and_then(|kt| (Mat3::identity() * diagonal + kt * dt).cholesky()) {
            Some(c) => c.solve(&rhs),
            None if stiffness.is_some() => (rhs - tissue) / diagonal,
            None => rhs / diagonal,
        };
        if v.norm() > max_speed {
            v *= max_speed / v.norm();
        }
        self.proxy_v = v;
        self.proxy += v * dt;
        let force = (self.proxy - device) * k + (self.proxy_v - device_v) * b;
        CouplingOut { force, device_v }
    }

    /// Advances the proxy by `dt` \[s\] against a local model of the tissue (the multirate loop,
    /// [`crate::multirate`]): the force `weight (F0 - K (x - x0))` of `model` at the proxy's
    /// *new* position, taken implicitly with the coupling, so that the step is stable for any
    /// positive semi-definite `K` at any rate:
    /// ```text
    /// ((m/dt + b + k dt) I + w K dt) v' = (m/dt) v + w (F0 - K (x - x0)) + k (x_d - x) + b v_d
    /// ```
    /// The proxy's speed is capped at `max_speed` \[m/s\] (the simulated tool's step per physics
    /// tick times the physics' rate). Returns the force to render (as [`VirtualCoupling::step`]).
    pub fn step_local(&mut self, device: &Vec3, model: &crate::multirate::LocalModel, weight: f64, dt: f64, max_speed: f64) -> CouplingOut {
        let tissue = (model.force - model.stiffness * (self.proxy - model.tool)) * weight;
        self.advance(device, &tissue, Some(model.stiffness * weight), dt, max_speed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// At rest against a constant tissue force the device feels exactly that force (a coupling
    /// that renders the spring's stretch with the wrong sign, or drops the tissue's force,
    /// would not).
    #[test]
    fn static_contact_renders_the_tissue_force() {
        let mut c = VirtualCoupling::new(CouplingParams::default(), Vec3::zeros());
        let tissue = Vec3::new(0.0, 0.0, 1.5);
        let mut out = c.step(&Vec3::zeros(), &tissue, 1e-3, 1e3);
        for _ in 0..5000 {
            out = c.step(&Vec3::zeros(), &tissue, 1e-3, 1e3);
        }
        assert!((out.force - tissue).norm() < 1e-9, "{:?}", out.force);
        assert!((c.proxy.z - 1.5 / 300.0).abs() < 1e-9);
    }

    /// Free space: the proxy follows the device and the rendered force decays to zero.
    #[test]
    fn free_space_follows() {
        let mut c = VirtualCoupling::new(CouplingParams::default(), Vec3::zeros());
        let d = Vec3::new(0.01, 0.0, 0.0);
        for _ in 0..2000 {
            c.step(&d, &Vec3::zeros(), 1e-3, 1e3);
        }
        assert!((c.proxy - d).norm() < 1e-9);
    }
}
