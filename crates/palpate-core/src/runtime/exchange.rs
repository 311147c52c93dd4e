//! The shell's reactions on the core, made implicit to first order inside the core's step.
//!
//! The particles are sub-stepped with the core held where the tick found it; their coupling
//! springs' reactions are then applied to the core over its 1 ms step. Taken explicitly, that
//! exchange is a spring of stiffness `k sum_p w_p^2` on a core node of mass `m` integrated with
//! forward forces, and it diverges, alternating tick by tick, once `k sum_p w_p dt^2` passes about
//! `m / 2` (measured on a thick slab: the alternation grew 4.4x a tick, VALIDATION.md). Capped at
//! that bound ([`super::SimOptions::implicit_exchange`] false), the springs are 10-20x below the
//! tissue's `E h` on every shipped wall (Rodero 2.9 N/m against 49), and the shell hangs on the
//! core by springs far softer than the tissue: its force grows 1.7x, not 2x, for twice the Young's
//! modulus.
//!
//! By default ([`super::SimOptions::implicit_exchange`] true) the springs keep the tissue's
//! stiffness and the core's step takes, as a potential,
//!
//! ```text
//! U(x) = 1/2 k sum_{p coupled, active} | sum_j w_pj (x_j - x*_j) - c(x) |^2,
//! x* = x0 + dt v0,   c(x) = sum_a m_a (x_a - x*_a) / sum_a m_a
//! ```
//!
//! the springs' own dependence on the core's motion this tick, linearised about the core's
//! predicted (inertial) position `x*`: an added inertia `k dt^2` per spring. It vanishes when the
//! core is at rest or moves steadily, so a held press settles where the explicit springs put it
//! (the force is the full springs' force); it damps nothing; and the alternation, an acceleration
//! that flips sign each tick, meets the springs' full stiffness implicitly, which no `dt` up to
//! [`INERTIA_TIME`] makes unstable. On a core with no held node, subtracting the mass-weighted
//! mean deviation `c` makes `U` invariant under a rigid translation (its forces sum to zero), so a
//! free body's linear momentum stays exact; a held core (the runtime's default) takes `c = 0`,
//! where the held nodes take the momentum anyway and the mean's dense term would cost the step an
//! iteration (it spreads `k sum_p w_p m_a / M` over every node: about 10% of the gradient on
//! Rodero, which the factor cannot hold). The springs' damping stays explicit (it is below the
//! stiffness's `k dt` at the 1 ms tick).
//!
//! Its cost. The core's step is preconditioned by its factorised matrix, and the springs are
//! 8x a core node's inertia on Rodero: left out of it, the step that was one quasi-Newton
//! iteration took 2.6 (Rodero's tick, 200 active, 0.65 ms mean, p99 1.57 ms:
//! `examples/tick_profile.rs`). So each spring is offered to the factor as a rank-one term
//! ([`CorePotential::stiffness_terms`], under its particle's index), which the integrator holds
//! and keeps current with a rank update per particle that enters or leaves (`integrate/factor.rs`,
//! `Ldl::update`): the step takes one iteration again (1.004 a tick over the same palpation).
//! Held only at the factor's refreshes, the set aged as particles came and went and the steps
//! took two (0.45 ms, p99 0.61 ms).
//!
//! The added inertia is `k min(dt, INERTIA_TIME)^2` a spring: the full implicit share at the
//! haptic 1 kHz tick and faster, a fixed inertia at slower ticks. With the full share at a 4 ms
//! physics tick (the multirate loop at 250 Hz) the inertia, 16x the 1 kHz one, made the core ring
//! slowly under a held press (period about 0.2 s, +-0.1 N on a 0.65 N press on the ellipsoids,
//! `palpate-haptics/tests/multirate.rs`); capped, the hold is within 6% of the 1 kHz loop's and
//! steady (past 1 ms the exchange's stability rests on that test, not on this argument). Referring the springs to the core's start position instead (a damper `k dt`) made the
//! press creep (0.79 N at the hold against 0.68, settling over seconds), and to the particles'
//! own motion, unstable.

use super::sim::Sim;
use crate::integrate::{CorePotential, StiffnessTerm};
use crate::math::Vec3;

/// The tick \[s\] up to which the springs' implicit share is whole (module docs).
pub const INERTIA_TIME: f64 = 1e-3;

/// The implicit share of the coupling springs of the active, coupled particles (module docs).
pub(crate) struct ShellReaction<'a> {
    pub sim: &'a Sim,
    /// The active particles (the coupled ones among them take part).
    pub active: &'a [usize],
    /// The core's predicted positions `x0 + dt v0` \[m\], `(n_nodes)`.
    pub predicted: &'a [Vec3],
    /// The core's total mass \[kg\].
    pub total_mass: f64,
    /// The springs' share taken implicitly, `min(1, (INERTIA_TIME / dt)^2)`.
    pub share: f64,
    /// Whether the mass-weighted mean deviation is subtracted (a core with no held node only:
    /// see the module docs).
    pub mean: bool,
}

impl<'a> ShellReaction<'a> {
    /// The reaction of the coupled particles in `active` on a core at `x`, `v`, stepped by `dt`
    /// (none with the exchange explicit: `SimOptions::implicit_exchange` false); `predicted` is
    /// filled with `x + dt v`.
    pub fn new(sim: &'a Sim, active: &'a [usize], x: &[Vec3], v: &[Vec3], dt: f64, predicted: &'a mut [Vec3]) -> Self {
        let active = if sim.options.implicit_exchange { active } else { &[] };
        for ((o, x), v) in predicted.iter_mut().zip(x).zip(v) {
            *o = x + dt * v;
        }
        let mean = sim.core.is_free_body();
        ShellReaction { sim, active, predicted, total_mass: sim.core.masses().iter().sum(), share: (INERTIA_TIME / dt).min(1.0).powi(2), mean }
    }

    /// True when no coupled particle is active (the potential is zero).
    pub fn is_empty(&self) -> bool {
        !self.active.iter().any(|&p| self.sim.coupled[p])
    }
}

impl CorePotential for ShellReaction<'_> {
    fn energy_forces(&self, x: &[Vec3], f: &mut [Vec3]) -> f64 {
        if self.active.is_empty() {
            return 0.0;
        }
        let (sim, pred) = (self.sim, self.predicted);
        let masses = sim.core.masses();
        let k = sim.coupling.stiffness * self.share;
        let mut c = Vec3::zeros();
        if self.mean {
            for ((xa, pa), &m) in x.iter().zip(pred).zip(masses) {
                c += m * (xa - pa);
            }
            c /= self.total_mass;
        }
        let (mut u, mut total) = (0.0, Vec3::zeros());
        for &p in self.active.iter().filter(|&&p| sim.coupled[p]) {
            let (n, w) = sim.particle_tie.tie(p);
            let mut d = -c;
            for j in 0..3 {
                let a = n[j] as usize;
                d += w[j] * (x[a] - pred[a]);
            }
            u += 0.5 * k * d.norm_squared();
            let g = k * d;
            total += g;
            for j in 0..3 {
                f[n[j] as usize] -= w[j] * g;
            }
        }
        // The mean's share: -dU/dx_a gains m_a / M times the sum of the springs' gradients.
        if self.mean {
            let s = total / self.total_mass;
            for (fa, &m) in f.iter_mut().zip(masses) {
                *fa += m * s;
            }
        }
        u
    }

    fn translation_invariant(&self) -> bool {
        self.mean
    }

    /// Each coupled active particle's spring, `k (w (x) I)(w (x) I)^T` on its tie's nodes, under the
    /// particle's index. The mean's dense part (rank three, `k / M` small; a free core only) is
    /// left out: the factor only needs to be near the Hessian.
    fn stiffness_terms(&self, emit: &mut dyn FnMut(StiffnessTerm)) {
        let k = self.sim.coupling.stiffness * self.share;
        for &p in self.active.iter().filter(|&&p| self.sim.coupled[p]) {
            let (n, w) = self.sim.particle_tie.tie(p);
            emit(StiffnessTerm { id: p as u32, nodes: n.map(|a| a as usize), weights: w, stiffness: k });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hybrid::{build, shapes, HybridOptions};
    use crate::material::{Damping, Elasticity, Material};
    use crate::runtime::SimOptions;

    fn sim() -> Sim {
        let wall = shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 3).unwrap();
        let model = build(&wall, &HybridOptions { spacing: crate::hybrid::Spacing::Count(3000), ..HybridOptions::default() }).unwrap();
        let tissue = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
        Sim::new(model, tissue, SimOptions::default()).unwrap()
    }

    /// The forces are minus the energy's gradient (central differences) and the energy is zero at
    /// the prediction, with the mean subtracted (a free core) or not (a held one); with it the
    /// forces sum to zero (a rigid translation changes nothing), without it they do not.
    #[test]
    fn shell_reaction_forces_are_its_energy_gradient_and_sum_to_zero() {
        let sim = sim();
        assert!(!sim.core.is_free_body());
        let n = sim.core.n_nodes();
        let x0: Vec<Vec3> = sim.hybrid.core_points.clone();
        let v: Vec<Vec3> = x0.iter().map(|p| Vec3::new(0.3 * p.y, -0.2 * p.z, 0.1 * p.x)).collect();
        let active: Vec<usize> = (0..sim.hybrid.particles.len()).filter(|&p| sim.coupled[p]).step_by(3).collect();
        assert!(active.len() > 20, "{} coupled particles", active.len());
        let mut pred = vec![Vec3::zeros(); n];
        let held = ShellReaction::new(&sim, &active, &x0, &v, 1e-3, &mut pred);
        assert!(!held.mean && !held.translation_invariant());
        for mean in [true, false] {
            let r = ShellReaction { mean, ..held };
            let mut f = vec![Vec3::zeros(); n];
            assert_eq!(r.energy_forces(r.predicted, &mut f), 0.0);
            let x: Vec<Vec3> = r
                .predicted
                .iter()
                .map(|p| p + Vec3::new(1e-4 * (p.y * 90.0).sin(), 2e-4 * (p.z * 70.0).cos(), -1e-4 * (p.x * 50.0).sin()))
                .collect();
            let mut f = vec![Vec3::zeros(); n];
            let u = r.energy_forces(&x, &mut f);
            assert!(u > 0.0);
            let sum: Vec3 = f.iter().sum();
            let scale = f.iter().map(|g| g.norm()).fold(0.0, f64::max);
            let shifted: Vec<Vec3> = x.iter().map(|p| p + Vec3::new(3e-3, -1e-3, 2e-3)).collect();
            let us = r.energy_forces(&shifted, &mut vec![Vec3::zeros(); n]);
            if mean {
                assert!(sum.norm() <= 1e-12 * scale * n as f64, "the forces sum to {sum:?} (largest {scale:e})");
                assert!((us - u).abs() <= 1e-9 * u, "translated: {us:e} against {u:e}");
            } else {
                assert!(sum.norm() > 1e-3 * scale, "without the mean the forces should not sum to zero");
            }
            let eps = 1e-8;
            let mut worst = 0.0f64;
            for a in (0..n).step_by(5) {
                for d in 0..3 {
                    let (mut xp, mut xm) = (x.clone(), x.clone());
                    xp[a][d] += eps;
                    xm[a][d] -= eps;
                    let (up, um) = (r.energy_forces(&xp, &mut vec![Vec3::zeros(); n]), r.energy_forces(&xm, &mut vec![Vec3::zeros(); n]));
                    let fd = -(up - um) / (2.0 * eps);
                    worst = worst.max((fd - f[a][d]).abs() / scale);
                }
            }
            assert!(worst < 1e-6, "mean {mean}: finite differences differ by {worst:e} of the largest force");
        }
    }

    /// The springs offered to the factor are the energy's Hessian without the mean: for a held
    /// core, `u^T H u` from the terms equals twice the energy at `x* + u` (a quadratic).
    #[test]
    fn shell_reaction_terms_are_its_hessian() {
        let sim = sim();
        let n = sim.core.n_nodes();
        let x0: Vec<Vec3> = sim.hybrid.core_points.clone();
        let v = vec![Vec3::zeros(); n];
        let active: Vec<usize> = (0..sim.hybrid.particles.len()).filter(|&p| sim.coupled[p]).step_by(2).collect();
        let mut pred = vec![Vec3::zeros(); n];
        let r = ShellReaction::new(&sim, &active, &x0, &v, 1e-3, &mut pred);
        let u: Vec<Vec3> = x0.iter().map(|p| Vec3::new((p.y * 90.0).sin(), (p.z * 70.0).cos(), (p.x * 50.0).sin()) * 1e-4).collect();
        let x: Vec<Vec3> = x0.iter().zip(&u).map(|(a, b)| a + b).collect();
        let energy = r.energy_forces(&x, &mut vec![Vec3::zeros(); n]);
        let mut quad = 0.0;
        let mut count = 0;
        r.stiffness_terms(&mut |t| {
            let wu: Vec3 = (0..3).map(|j| t.weights[j] * u[t.nodes[j]]).sum();
            quad += t.stiffness * wu.norm_squared();
            count += 1;
        });
        assert_eq!(count, active.len());
        assert!((0.5 * quad - energy).abs() <= 1e-12 * energy, "{} against {energy:e}", 0.5 * quad);
    }
}
