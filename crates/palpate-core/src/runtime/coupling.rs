//! The two-way coupling of the active particles and the FEM core on the core faces (paper §6.1),
//! written so that linear momentum is conserved exactly.
//!
//! **What the paper does and what this does instead.** The paper averages the displacements of
//! the particles that cross a core face onto the face's nodes with barycentric weights and moves
//! the boundary particles with the face along its normal: a kinematic exchange, which neither
//! conserves momentum nor has an energy. Here each active particle of the first lattice layer over
//! the core (within [`super::SimOptions::coupling_depth_spacings`] of its face at rest) is tied to
//! the point of its face where it sat at rest ([`super::Embedding`]) by a damped spring of energy
//! `k/2 |x_tie - x_p|^2`: the particle receives `f = k (x_tie - x_p) + c (v_tie - v_p)` and the
//! face nodes `-w_a f` with the tie's barycentric weights, which sum to one. Every force is thus
//! one of an equal and opposite pair (linear momentum exact), the elastic part derives from an
//! energy (the spread is the exact transpose of the tie), and the damping only dissipates. The
//! paper's two rules are the stiff limit of this spring: particles over a face move with it, and
//! the face feels the particles' push, averaged with the same weights.

use super::embed::Embedding;
use crate::math::Vec3;

/// The coupling springs' constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coupling {
    /// Spring stiffness \[N/m\].
    pub stiffness: f64,
    /// Spring damping \[N s/m\].
    pub damping: f64,
}

impl Coupling {
    /// Springs as stiff as the tissue between two lattice neighbours (`E * spacing`, \[N/m\]),
    /// damped at `zeta` of critical for a particle of mass `mass` \[kg\] on a fixed face.
    /// Explicit sub-steps of `h` stay stable while `sqrt(k / m) h < 2`; the tissue's own
    /// stiffness already sets `h` (the particles' stable step), so this spring does not lower it.
    pub fn for_tissue(young: f64, spacing: f64, mass: f64, zeta: f64) -> Coupling {
        let stiffness = young * spacing;
        Coupling { stiffness, damping: 2.0 * zeta * (stiffness * mass).sqrt() }
    }

    /// The spring energy of particle `p` at `x` against its tie at core positions `x_core` \[J\].
    pub fn energy(&self, tie: &Embedding, p: usize, x: &Vec3, x_core: &[Vec3]) -> f64 {
        0.5 * self.stiffness * (tie.position(p, x_core) - x).norm_squared()
    }

    /// For each coupled particle in `active`: adds the spring force to `f_particles[p]` and its
    /// opposite, spread by the tie's weights, to `f_core` \[N\]. `x`, `v`: particle positions and
    /// velocities; `x_core`, `v_core`: the core's.
    #[allow(clippy::too_many_arguments)]
    pub fn add_forces(
        &self,
        tie: &Embedding,
        coupled: &[bool],
        active: &[usize],
        x: &[Vec3],
        v: &[Vec3],
        x_core: &[Vec3],
        v_core: &[Vec3],
        f_particles: &mut [Vec3],
        f_core: &mut [Vec3],
    ) {
        for &p in active {
            if !coupled[p] {
                continue;
            }
            let f = self.force(&tie.position(p, x_core), &tie.velocity(p, x_core, v_core), &x[p], &v[p]);
            f_particles[p] += f;
            tie.spread(p, -f, x_core, f_core);
        }
    }

    /// The spring's force on a particle at `x` with velocity `v` whose tie is at `tie_x` moving
    /// at `tie_v` \[N\] (the tie receives the opposite).
    #[inline]
    pub fn force(&self, tie_x: &Vec3, tie_v: &Vec3, x: &Vec3, v: &Vec3) -> Vec3 {
        self.stiffness * (tie_x - x) + self.damping * (tie_v - v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> (Embedding, Vec<Vec3>) {
        let core = vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.01, 0.0, 0.0), Vec3::new(0.0, 0.01, 0.0)];
        let rest = [Vec3::new(0.002, 0.003, 0.001), Vec3::new(0.004, 0.001, 0.0015)];
        (Embedding::project(&core, &[[0, 1, 2]], &[0, 0], &rest), core)
    }

    #[test]
    fn forces_are_equal_and_opposite_and_derive_from_the_energy() {
        let (tie, core) = setup();
        let c = Coupling { stiffness: 40.0, damping: 0.0 };
        let x = vec![Vec3::new(0.0021, 0.0028, 0.0013), Vec3::new(0.0042, 0.0009, 0.0012)];
        let v = vec![Vec3::zeros(); 2];
        let xc: Vec<Vec3> = core.iter().enumerate().map(|(k, p)| p + Vec3::new(1e-4 * k as f64, -2e-4, 5e-5)).collect();
        let (mut fp, mut fc) = (vec![Vec3::zeros(); 2], vec![Vec3::zeros(); 3]);
        c.add_forces(&tie, &[true, true], &[0, 1], &x, &v, &xc, &[Vec3::zeros(); 3], &mut fp, &mut fc);
        let total: Vec3 = fp.iter().chain(&fc).sum();
        assert!(total.norm() <= 1e-15 * fp[0].norm().max(1e-30), "{total:?}");
        // f = -dE/dx for the particle and for the core nodes.
        let e = |x: &[Vec3], xc: &[Vec3]| (0..2).map(|p| c.energy(&tie, p, &x[p], xc)).sum::<f64>();
        let h = 1e-9;
        for a in 0..3 {
            let mut xp = x.clone();
            xp[0][a] += h;
            let mut xm = x.clone();
            xm[0][a] -= h;
            let fd = -(e(&xp, &xc) - e(&xm, &xc)) / (2.0 * h);
            assert!((fd - fp[0][a]).abs() <= 1e-6 * fp[0].norm(), "particle: {fd} vs {}", fp[0][a]);
            let mut cp = xc.clone();
            cp[1][a] += h;
            let mut cm = xc.clone();
            cm[1][a] -= h;
            let fd = -(e(&x, &cp) - e(&x, &cm)) / (2.0 * h);
            assert!((fd - fc[1][a]).abs() <= 1e-6 * fc[1].norm().max(1e-12), "core: {fd} vs {}", fc[1][a]);
        }
    }

    #[test]
    fn damping_opposes_the_relative_velocity_and_uncoupled_particles_feel_nothing() {
        let (tie, core) = setup();
        let c = Coupling { stiffness: 0.0, damping: 0.3 };
        let x: Vec<Vec3> = (0..2).map(|p| tie.position(p, &core)).collect();
        let v = vec![Vec3::new(0.0, 0.0, 0.1), Vec3::new(0.0, 0.0, 0.1)];
        let (mut fp, mut fc) = (vec![Vec3::zeros(); 2], vec![Vec3::zeros(); 3]);
        c.add_forces(&tie, &[true, false], &[0, 1], &x, &v, &core, &[Vec3::zeros(); 3], &mut fp, &mut fc);
        assert!(fp[0].dot(&v[0]) < 0.0);
        assert_eq!(fp[1], Vec3::zeros());
        assert!((fc.iter().sum::<Vec3>() + fp[0]).norm() < 1e-15);
    }
}
