//! Selective mass scaling: the explicit shell's step is set by its stiffest mode, and on a lattice
//! shell that mode sits on a few poorly supported particles (a lattice's corners and rims: ~10
//! particles carry 95% of the top mode's energy on the paper's ellipsoids, `runtime/stability.rs`),
//! whose `omega^2` is 1.5-3x the bulk's. Adding mass to those particles alone lowers the top
//! frequency to the bulk's, so every sub-step of every tick is longer, at the price of a little
//! inertia where the lattice is poorest. This is the standard remedy of explicit structural
//! dynamics (selective or "conventional" mass scaling: LS-DYNA's `DT2MS`, Abaqus/Explicit's
//! `*FIXED MASS SCALING`; Olovsson, Simonsson and Unosson 2005, Int. J. Numer. Meth. Eng. 64).
//!
//! **Which particles, how much.** For each free particle `i`, `G_i` is the largest absolute row
//! sum of its three rows of the rest-linearised stiffness `K` over the free particles (computed
//! exactly, by probing `K` with a unit displacement of `i`: only the stresses of `i` and its
//! neighbours change). Gershgorin's theorem bounds every eigenvalue of `M^-1 K` by
//! `max_i G_i / m_i`, so raising `m_i` to `G_i / r` wherever `G_i / m_i > r` proves
//! `omega_max^2 <= r` for the scaled body ([`ParticleModel::mass_scaling`] reports what was
//! added). The target `r` is a quantile of the rates `G_i / m_i`
//! ([`super::ParticleModelBuilder::mass_scaling`]): the stiffest few percent of the particles are
//! brought down to the rest. The added mass is kept only where it pays: when it lowers the
//! power-iteration `omega_max^2` by at least [`WORTH_IT`] (a regular lattice's stiffest particles
//! are no stiffer than its bulk's top mode: there the masses stay physical).
//!
//! **What it changes.** Statics not at all (the stiffness and volumes are untouched: masses enter
//! the step only as inertia); dynamics where mass was added: a scaled particle's own frequencies
//! drop by `sqrt(m_i / m_i')`. Momentum and energy stay exact for the scaled masses (the step and
//! [`ParticleModel::momentum`] use them). The hybrid runtime carries the shell's physical mass on
//! the core (`runtime/sim.rs`), not the scaled one.

use super::model::ParticleModel;
use super::pair_loop::{self, Cols, P4};

/// What [`super::ParticleModelBuilder::mass_scaling`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MassScaling {
    /// The quantile of the particles' rates `G_i / m_i` asked for (0 when off).
    pub quantile: f64,
    /// The target rate `r` \[1/s^2\]: a proven bound of the scaled body's `omega_max^2`.
    pub target_rate2: f64,
    /// Particles whose mass was raised.
    pub scaled: usize,
    /// Mass added over the whole body \[kg\], and as a fraction of its physical mass.
    pub added_mass: f64,
    pub added_fraction: f64,
    /// The largest factor `m_i' / m_i`.
    pub max_factor: f64,
    /// The body's `omega_max^2` \[1/s^2\] (power iteration) without and with the added mass.
    pub omega2_before: f64,
    pub omega2_after: f64,
    /// Whether the masses were kept scaled: only when that lowers `omega_max^2` by at least
    /// [`WORTH_IT`] (on a regular lattice, such as the synthetic ventricle's, the stiffest
    /// particles are no stiffer than the bulk's top mode, and added mass would buy nothing).
    pub applied: bool,
}

/// The least relative drop of `omega_max^2` for which the added mass is kept (10%: about 5% fewer
/// sub-steps).
pub const WORTH_IT: f64 = 0.10;

impl ParticleModel {
    /// Per particle, Gershgorin's row sum of the rest-linearised stiffness \[N/m\]: the largest
    /// over its three rows of `sum_(k,b) |K_(ia),(kb)|`, `k` over the free particles; 0 for fixed
    /// particles. `K` is symmetric (the forces are an energy's gradient), so row `(i, a)` is read
    /// as the forces of a unit displacement of particle `i` along `a`. O(n * neighbours^2).
    pub fn stiffness_row_sums(&self) -> Vec<f64> {
        let n = self.n_particles();
        let zero: Cols = [[0.0; 4]; 3];
        let mut u: Vec<P4> = vec![[0.0; 4]; n];
        let mut b: Vec<Cols> = vec![zero; n];
        let mut mark = vec![usize::MAX; n];
        let (mut s1, mut s2) = (Vec::new(), Vec::new());
        let mut out = vec![0.0; n];
        for j in 0..n {
            if self.fixed[j] {
                continue;
            }
            // S1: the particles whose strain sees u_j (j and its neighbours: the lists are
            // symmetric); S2: those whose force sees S1's stresses or u_j (S1 and their neighbours).
            s1.clear();
            s1.push(j);
            s1.extend_from_slice(self.neighbours(j));
            s2.clear();
            for &i in &s1 {
                for &k in std::iter::once(&i).chain(self.neighbours(i)) {
                    if mark[k] != j {
                        mark[k] = j;
                        s2.push(k);
                    }
                }
            }
            let mut best = 0.0f64;
            for a in 0..3 {
                u[j][a] = 1.0;
                for &i in &s1 {
                    b[i] = pair_loop::stress_of(self, i, &u, true);
                }
                let mut sum = 0.0;
                for &k in s2.iter().filter(|&&k| !self.fixed[k]) {
                    let f = pair_loop::force_of(self, k, &u, &b, &self.gamma);
                    sum += f[0].abs() + f[1].abs() + f[2].abs();
                }
                best = best.max(sum);
                for &i in &s1 {
                    b[i] = zero;
                }
                u[j][a] = 0.0;
            }
            out[j] = best;
        }
        out
    }

    /// What selective mass scaling did: all zeros when it was off; with `applied` false, what it
    /// would have added, had that lowered the top frequency enough to be kept.
    pub fn mass_scaling(&self) -> &MassScaling {
        &self.scaling
    }

    /// [`Self::scale_masses`], kept only if it lowers `omega_max^2` by [`WORTH_IT`] (the stable
    /// step was computed for the physical masses; it is recomputed for the scaled ones, and put
    /// back with them otherwise).
    pub(super) fn scale_masses_if_worth_it(&mut self, quantile: f64) {
        let (mass, inv_mass) = (self.mass.clone(), self.inv_mass.clone());
        let (dt, omega, damping) = (self.stable_dt, self.omega_max, self.damping_max);
        self.scale_masses(quantile);
        let mut s = self.scaling;
        s.omega2_before = omega * omega;
        if s.scaled > 0 {
            self.compute_stable_dt();
            s.omega2_after = self.omega_max * self.omega_max;
        } else {
            s.omega2_after = s.omega2_before;
        }
        s.applied = s.scaled > 0 && s.omega2_after <= (1.0 - WORTH_IT) * s.omega2_before;
        if !s.applied {
            (self.mass, self.inv_mass) = (mass, inv_mass);
            (self.stable_dt, self.omega_max, self.damping_max) = (dt, omega, damping);
        }
        self.scaling = s;
    }

    /// Raise every free particle's mass to at least `G_i / r`, `r` the `quantile` of the free
    /// particles' rates `G_i / m_i` (see the module docs). Leaves the stable step to the caller.
    fn scale_masses(&mut self, quantile: f64) {
        let g = self.stiffness_row_sums();
        let mut rates: Vec<f64> = (0..self.n_particles()).filter(|&i| !self.fixed[i]).map(|i| g[i] / self.mass[i]).collect();
        if rates.is_empty() {
            return;
        }
        rates.sort_by(f64::total_cmp);
        let at = ((quantile * (rates.len() - 1) as f64).round() as usize).min(rates.len() - 1);
        let r = rates[at];
        if !(r > 0.0 && r.is_finite()) {
            return;
        }
        let physical: f64 = self.mass.iter().sum();
        let mut s = MassScaling { quantile, target_rate2: r, max_factor: 1.0, ..Default::default() };
        for i in (0..self.n_particles()).filter(|&i| !self.fixed[i]) {
            let need = g[i] / r;
            if need > self.mass[i] {
                s.scaled += 1;
                s.added_mass += need - self.mass[i];
                s.max_factor = s.max_factor.max(need / self.mass[i]);
                self.mass[i] = need;
                self.inv_mass[i] = 1.0 / need;
            }
        }
        s.added_fraction = s.added_mass / physical;
        self.scaling = s;
    }
}
