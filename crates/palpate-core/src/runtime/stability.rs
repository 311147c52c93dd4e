//! How many particle sub-steps a tick needs: the shell's explicit Verlet (eq. 33) is stable while
//! every mode satisfies the central-difference limit `h <= 2 / omega (sqrt(1 + zeta^2) - zeta)`,
//! and a touched shell has stiffer modes than the rest-linearised one the particle body's own
//! step count ([`crate::meshfree::ParticleModel::substeps`]) is computed from.
//!
//! Three things stiffen it, each bounded here, once a tick, allocation-free:
//! - **Stretch.** St. Venant-Kirchhoff stiffens in tension: in a uniaxial stretch `s`,
//!   `P = M s (s^2 - 1) / 2` (`M = lambda + 2 mu`), whose slope `M (3 s^2 - 1) / 2` is the rest
//!   modulus times [`stiffening`]`(s^2)`. A 5 mm sphere pressed 10 mm into the ventricle
//!   stretches the shell at its rim by ~30%, doubling `omega^2`: with the rest count the
//!   particles there diverged (measured: `examples/touch.rs`, undamped, 9 mm into a press). The
//!   largest `s^2` over the active particles is bounded by Gershgorin's row sums of
//!   `C = F^T F` ([`stretch_bound`]), taken at the start of the tick. The bound's slack is needed:
//!   with the exact largest eigenvalue of `C` instead (one sub-step fewer at a 5 mm press), a press
//!   toward 2 N diverged at 20 mm on the ventricle (tests/runtime_hand.rs). The uniaxial slope
//!   does not bound every mode of a strongly deformed shell; a tighter, proven bound is open.
//!   (Measured too: in a 15 mm press a few particles move at 2-5 m/s against their ties, a local
//!   mode the force does not feel: tick-to-tick force changes stay under 0.02 N. Re-running such a
//!   tick with twice the sub-steps, tried as a safety net, made the force jump by 0.15-0.5 N
//!   instead, and was taken out.)
//! - **The runtime's springs** on a particle: the tool's penalty (through the skin, see
//!   [`super::tick`](mod@super::tick)), the coupling spring and the confinement wall, each explicit. Their rates
//!   `k / m` (and `c / m` for the damping) add to the internal `omega^2` (Weyl's inequality for
//!   a sum of symmetric stiffnesses in the mass metric). The coupling and the wall are bounded
//!   once, at [`Shell::new`]; the tool's share of each particle is the Gershgorin row sum of the
//!   skin's spread (`sum_v k w_p / (W_v m_p)` over the skin vertices within reach), per tick.
//! - **Viscosity**: the material's rate scales with the stretch like the stiffness (`F^T L`
//!   under `F`), plus the springs' dampers.
//!
//! The count is capped ([`super::SimOptions::max_substeps`]): past it a tick costs more than a
//! haptic tick has, and a tick that still diverges is contained (restored and reported): as
//! `StepError::Diverging` at the sub-step where a particle passes the physical speed bound
//! (50 P-wave speeds, [`crate::divergence`]), before anything overflows; measured with the cap
//! forced to 9 on the synthetic ventricle, the tick after the first past one wave speed
//! (tests/runtime_hand.rs).
//!
//! **Open (found 2026-11-26, fifth session): region entries in a press deeper than the wall.**
//! The bound covers the active particles; their inactive neighbours (the ring) sit at their ties.
//! 20 mm into the synthetic ventricle's 6 mm wall, active particles are carried one to two
//! spacings from their ties, and ring particles beside them are inverted (`det F` to -13,
//! `s^2` ~370). When such a particle's region enters, its stiffening asks ~20 times the rest
//! count, past the cap, and the tick diverges (contained and reported). The shipped models pass
//! the press toward 2 N (tests/runtime_hand.rs), but a model built with different ties (the
//! outer triangles sorted before the build's stages, tried) failed it at 20 mm; starting
//! entering particles at their active neighbours' displacement moved the failure to another
//! entry. Counting the ring in the bound (tried) took 30-47 sub-steps a tick on average in an
//! ordinary 4 mm press on Rodero, against 10-11: the ring is always distorted. A boundary for the active zone that follows it, or entries deferred while
//! the ring is inverted, are the candidates.
//!
//! **Measured (2026-11-26, sixth session): the same failure at most probe points, and why.**
//! `examples/press_sweep.rs` presses toward 2 N (the test's script) at 24 points of the
//! synthetic ventricle (4 heights x 6 angles), undamped: 18 of 24 shell steps diverged, from
//! 17-20 mm of travel at mid-height and from 6-11 mm 6 mm below the held base (with the paper's
//! damping they hold but take the 64 sub-step cap). Traced at the worst point: the SVK core's
//! elements between the tool and the base flatten (volume ratio 0.85 -> 0.06 over ~5 ticks, a
//! tick-to-tick alternation first), the faces under the shell turn with them, and the ties,
//! rigid in their faces' frames, carry the ring and the entering particles to places whose
//! deformation gradients are inverted or stretched 5-8x (`s^2` to 60), past what 64 sub-steps
//! hold. Softer or 10x stiffer coupling springs, entering particles at their active neighbours'
//! displacement, and a Neo-Hookean core (which flattens later, ~11 mm) each moved the failure,
//! none removed it. What would: a core that resists flattening as the shell's law does (its
//! compression barrier) together with ties that interpolate the core's deformation smoothly
//! across faces. Until then the tick sheds a failed shell ([`super::SimOptions::shell_fallback`],
//! tests/runtime_hand.rs `a_press_toward_2_n_beside_the_held_base_never_fails_a_tick`).
//!
//! **Measured (2026-11-27, seventh session): not the core's inversions.** With the shell's
//! compression barrier added to the core's St. Venant-Kirchhoff law (a trial, not kept), no core
//! element inverted at the press beside the base (without it: 6 at the shed, up to 190 at 20 mm
//! of travel), yet the shell failed at the same tick (155, 7.75 mm). What the shed leaves has
//! since been made smooth instead: the skin fades back to its ties (`SkinLift`), and the tool
//! meets the core inside its implicit step ([`super::core_contact`]); the force changes by
//! 0.03-0.15 N a tick at the switch and 0.01-0.11 N while the shell is off, against 0.65-3.2 N
//! and up to 1.5 N before (`examples/press_sweep.rs`, 18 shed points of the synthetic ventricle).
//!
//! **Measured (2026-11-27, twelfth session): what a shed is preceded by, and a per-particle
//! remedy that fails.** At the press beside the held base (`press_sweep ventricle damped`, 33.6 mm
//! high, 5.54 rad; shed at 6.9 mm of travel) the count sits at the 64 cap for ~17 ticks before
//! the shed, set by 2-5 poorly supported particles (9-12 neighbours) stretched to `s^2` 8-23,
//! which alone ask 100-250 sub-steps; 24-79 others ask more than 32; the ring beside them reaches
//! `s^2` 40-300. Demoting the particles that ask more than a limit to the ring for the tick
//! (placed at their ties, frozen, so their stiffness leaves the step; a trial, not kept) moved the
//! shed from 6.9 to 7.9 mm with the limit at 64, and made it worse below: with 32 and 20 the
//! snaps to the ties cascaded (100-3,000 particles demoted a tick) and the force jumped by
//! 0.25-1.8 N a tick, against 0.07 N at the shed without it.
//!
//! **Adopted since: selective mass scaling** (`crate::meshfree` `mass_scaling.rs`, on by default
//! through [`super::SimOptions::mass_scaling`]): the few poorly supported particles below get the
//! mass that brings their Gershgorin rate to the 95th percentile's, which lowers `omega_max^2`
//! (the `omega2` this module starts from) by 42% on the ellipsoids and 58% on the Rodero
//! ventricle, and by 2% on the synthetic ventricle (not kept there).
//!
//! **Where a lower count could come from** (measured 2026-11-25 on the paper's ellipsoids, 28,210
//! particles, before mass scaling). The rest-linearised `omega_max^2` is the whole shell's: its top mode
//! sits on ~10 poorly supported lattice particles (6-9 neighbours, 95% of the mode's mass-weighted
//! energy) in one spot, and a ball of the shell restricted to itself (the rest frozen, as an
//! active set is) has 0.30-0.47 of that eigenvalue at 4 mm and 0.52-0.67 at 8 mm, i.e. 20-45%
//! fewer sub-steps. But a restricted patch's eigenvalue is a lower bound of the active set's, not
//! an upper one; the proven per-particle bound (block Gershgorin rows of `M^-1 K`) is 0.72 of the
//! global eigenvalue there (15% fewer sub-steps). Holding the few-neighbour particles lowers the
//! global eigenvalue to 0.67 on the ellipsoids but only to 0.95 on the ventricle (holding 5-9% of
//! the shell). The paper's damping (`phi = psi = 1 Pa s`) costs the most: `zeta = 0.53` at the top
//! mode, 20 sub-steps instead of 13 undamped; a viscous term implicit in time would remove that
//! factor but needs a solve per sub-step.
//!
//! **Measured and dropped (2026-11-26): the exact damped limit.** For the lagged scheme
//! `M (v+ - v) = -h (K x + D v)` with `D` positive definite, an eigenvalue of the step can leave
//! the unit circle only at `z = -1` (on `|z| = 1` the imaginary part of `phi* (...) phi` forces
//! `sin theta = 0`), so the exact rest-linearised limit is `lambda_max(M^-1 (h^2 K + 2 h D)) <= 4`,
//! of which the rule above (`h^2 omega^2 + 2 h d <= 4`) is Weyl's upper bound. On the Rodero
//! shell (mass-scaled) the two differ by 0.3% at every sub-step count from 6 to 14: the stiffest
//! mode is also the most damped one (the poorly supported particles), so nothing is gained.

use super::confinement::Confinement;
use super::coupling::Coupling;
use crate::math::Mat3;
use crate::meshfree::{ParticleModel, STABILITY_SAFETY};

/// The shell's stability data, resolved once from the compiled particle body and the springs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shell {
    /// Rest-linearised `omega_max^2` of the particle body \[1/s^2\].
    pub omega2: f64,
    /// Rest-linearised viscous rate \[1/s\].
    pub damping: f64,
    /// Largest `(k_coupling + k_wall) / m` over the particles \[1/s^2\].
    pub spring_rate: f64,
    /// Largest `c_coupling / m` over the particles \[1/s\].
    pub spring_damping: f64,
}

impl Shell {
    /// From the particle body and the springs; `coupled[p]`: particle `p` has a coupling spring.
    pub fn new(particles: &ParticleModel, coupled: &[bool], coupling: &Coupling, wall: &Confinement) -> Shell {
        let (mut spring_rate, mut spring_damping) = (0.0f64, 0.0f64);
        for (p, &m) in particles.masses().iter().enumerate() {
            let (k, c) = if coupled[p] { (coupling.stiffness, coupling.damping) } else { (0.0, 0.0) };
            spring_rate = spring_rate.max((k + wall.stiffness) / m);
            spring_damping = spring_damping.max(c / m);
        }
        Shell { omega2: particles.omega_max().powi(2), damping: particles.damping_max(), spring_rate, spring_damping }
    }

    /// Sub-steps for a tick of `dt` \[s\] when the active particles' largest `s^2` is at most
    /// `stretch2` and the tool adds at most `contact_rate` \[1/s^2\] and `contact_damping` \[1/s\]
    /// to a particle; at least the rest count, at most `cap`.
    pub fn substeps(&self, dt: f64, stretch2: f64, contact_rate: f64, contact_damping: f64, cap: usize) -> usize {
        let s = stiffening(stretch2);
        let omega2 = self.omega2 * s + self.spring_rate + contact_rate;
        let d = self.damping * stretch2.max(1.0) + self.spring_damping + contact_damping;
        let h = critical_step(omega2, d) * STABILITY_SAFETY;
        let k = if h.is_finite() && h > 0.0 { (dt / h).ceil() } else { cap as f64 };
        (k as usize).clamp(1, cap.max(1))
    }
}

/// Central differences' critical step for `omega^2` and a velocity-lagged damping rate `d`.
fn critical_step(omega2: f64, d: f64) -> f64 {
    let omega = omega2.max(0.0).sqrt();
    if omega > 0.0 {
        let zeta = d / (2.0 * omega);
        2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta)
    } else if d > 0.0 {
        2.0 / d
    } else {
        f64::INFINITY
    }
}

/// St. Venant-Kirchhoff's tangent over its rest value in a stretch with `s^2 = stretch2`:
/// `(3 s^2 - 1) / 2`, never below 1 (compression softens it).
pub fn stiffening(stretch2: f64) -> f64 {
    (1.5 * stretch2 - 0.5).max(1.0)
}

/// An upper bound of the largest eigenvalue of `F^T F` (the squared largest principal stretch):
/// the largest absolute row sum (Gershgorin). Exact for a diagonal `F`.
pub fn stretch_bound(f: &Mat3) -> f64 {
    let c = f.transpose() * f;
    (0..3).map(|i| c[(i, 0)].abs() + c[(i, 1)].abs() + c[(i, 2)].abs()).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretch_bound_is_exact_on_diagonals_and_bounds_rotations() {
        let f = Mat3::from_diagonal(&crate::math::Vec3::new(1.3, 0.9, 1.0));
        assert!((stretch_bound(&f) - 1.69).abs() < 1e-12);
        // A rotation has every stretch 1: the bound is exactly 1 (C = I).
        let r = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        assert!((stretch_bound(&r) - 1.0).abs() < 1e-12);
        // A shear: the bound is at least the true largest eigenvalue.
        let mut s = Mat3::identity();
        s[(0, 1)] = 0.4;
        let c = s.transpose() * s;
        let top = c.symmetric_eigenvalues().max();
        assert!(stretch_bound(&s) >= top - 1e-12);
    }

    #[test]
    fn uniaxial_svk_slope_matches_the_stiffening() {
        // P(s) = M s (s^2 - 1) / 2 for M = 1: its slope by central differences.
        let p = |s: f64| s * (s * s - 1.0) / 2.0;
        for s in [1.0, 1.1, 1.3, 1.6] {
            let slope = (p(s + 1e-6) - p(s - 1e-6)) / 2e-6;
            assert!((slope - stiffening(s * s)).abs() < 1e-6, "s = {s}");
        }
    }

    #[test]
    fn the_critical_step_matches_the_particle_bodys_rule() {
        // No damping: 2 / omega. Damping alone: 2 / d.
        assert!((critical_step(4.0e8, 0.0) - 2.0 / 2.0e4).abs() < 1e-15);
        assert!((critical_step(0.0, 100.0) - 0.02).abs() < 1e-15);
        // Stiffer or more damped: a shorter step.
        assert!(critical_step(4.0e8, 1e3) < critical_step(4.0e8, 0.0));
    }
}
