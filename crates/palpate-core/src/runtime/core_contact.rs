//! The tool's contact with what moves with the core, taken inside the core's implicit step (the
//! incremental potential of [`crate::integrate::step_with_potential`]): the skin where no
//! particle carries it and the core's surface. With the shell on, those are the skin vertices
//! over no active particle or with no particle under their carrier triangles
//! ([`super::sim::SkinCarriers`]), and the core's surface where the tool has pushed the shell
//! aside; with the shell off ([`super::SimOptions::shell_fallback`])
//! the tool meets the coarse core through the skin alone.
//!
//! Why implicit: held over the core's 1 ms step, the explicit penalty (60 N/m a skin vertex) on
//! the core made the force chatter, with the shell on as with it off. With the shell on, measured
//! on the Rodero ventricle (`examples/press_sweep.rs`, the paper's damping, the tool held
//! 11.35 mm in at 4/5 of the height, 3.44 rad; 2026-11-27): the force alternated between 2.2 and
//! 4.8 N tick by tick for as long as the tool was held (median change 1.3 N a tick); with the core
//! frozen, or without those vertices' force, the same shell settled; with their contact in the
//! step the hold changes by at most 0.014 N a tick. With the shell off, measured with
//! `examples/press_sweep.rs` on the synthetic ventricle, undamped (2026-11-27): with the shell
//! off the largest tick-to-tick change of the force was 0.69-3.18 N at the 18 points whose shell
//! was shed, against 0.02-0.24 N with the shell on; the contact set alternated (23 <-> 61 skin
//! vertices a tick), and a tick of a quarter of a millisecond calmed it (a time-step limit, not
//! the tissue: a compression barrier in the core removed every inverted element and left the
//! chatter). In the potential the contact's stiffness is part of what the step minimises, so no
//! tick bound applies.
//!
//! The energy is the penalty's, `k d^2 / 2` per point (`d` the depth in the sphere, see
//! [`super::tool`]), over the skin vertices within reach (each at its tie, a function of the
//! core's nodes, [`super::embed::Embedding::position`]; the forces go to the nodes through the
//! tie's exact transpose, [`super::embed::Embedding::spread`]) and the core's surface nodes. The
//! approach damping is left out (backward Euler damps the contact's own oscillation). The tool
//! receives minus the sum of the point forces at the end of the step; on a body with no fixed
//! node, minus what the step gave the core (see [`super::tick`](mod@super::tick) step 5: the minimisation's
//! residual included, so that linear momentum stays exact).

use super::sim::Sim;
use super::tool::PointContact;
use crate::integrate::CorePotential;
use crate::math::Vec3;

/// The tool at `centre` against the skin vertices `skin` (at their ties) and the core's surface.
pub struct CoreContact<'a> {
    /// The compiled simulation (its tool's radius and stiffness, skin ties, core surface).
    pub sim: &'a Sim,
    /// The tool's centre \[m\], world frame.
    pub centre: Vec3,
    /// Skin vertices that may touch (indices into the outer surface).
    pub skin: &'a [usize],
    /// Core surface nodes that may touch (a subset of [`Sim::core_surface`]).
    pub core: &'a [usize],
    /// Per skin vertex, a constant offset \[m\] off its tie, times `lift_scale` (a shed shell's
    /// skin fading back to its ties; zeros: none).
    pub lift: &'a [Vec3],
    pub lift_scale: f64,
}

/// The forces a [`CoreContact`] gave at the end of a step.
#[derive(Debug, Clone, Copy, Default)]
pub struct CoreContactSum {
    /// Sum of the forces on the tissue \[N\] (the tool receives the opposite).
    pub force: Vec3,
    /// Skin vertices and core surface nodes in contact.
    pub skin_contacts: usize,
    pub core_contacts: usize,
    /// Deepest penetration \[m\].
    pub max_depth: f64,
}

impl CoreContact<'_> {
    /// Visit every point in contact at core positions `x`: `(is_skin, index, contact)`, the
    /// contact being the tool's penalty at rest ([`super::Tool::contact`] with no velocities:
    /// the damping is left out, see the module docs).
    fn each(&self, x: &[Vec3], mut visit: impl FnMut(bool, usize, PointContact)) {
        let tool = &self.sim.options.tool;
        let at_rest = Vec3::zeros();
        for &v in self.skin {
            let p = self.sim.skin.position(v, x) + self.lift_scale * self.lift[v];
            if let Some(c) = tool.contact(&self.centre, &at_rest, &p, &at_rest) {
                visit(true, v, c);
            }
        }
        for &a in self.core {
            if let Some(c) = tool.contact(&self.centre, &at_rest, &x[a], &at_rest) {
                visit(false, a, c);
            }
        }
    }

    /// The contact's forces at core positions `x` (the end of the step).
    pub fn sum(&self, x: &[Vec3]) -> CoreContactSum {
        let mut s = CoreContactSum::default();
        self.each(x, |skin, _, c| {
            s.force += c.force;
            if skin {
                s.skin_contacts += 1;
            } else {
                s.core_contacts += 1;
            }
            s.max_depth = s.max_depth.max(c.depth);
        });
        s
    }
}

impl CorePotential for CoreContact<'_> {
    fn energy_forces(&self, x: &[Vec3], f: &mut [Vec3]) -> f64 {
        let mut u = 0.0;
        self.each(x, |skin, i, c| {
            u += c.energy;
            if skin {
                self.sim.skin.spread(i, c.force, x, f);
            } else {
                f[i] += c.force;
            }
        });
        u
    }
}
