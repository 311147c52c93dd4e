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
//! The energy is the penalty's, `k_a A_v d^2 / 2` per skin vertex (`d` the depth in the sphere,
//! `A_v` the skin area the vertex carries, `k_a` the tool's stiffness per unit area, see
//! [`super::tool`]), over the skin vertices within reach (each at its tie, a function of the
//! core's nodes, [`super::embed::Embedding::position`]; the forces go to the nodes through the
//! tie's exact transpose, [`super::embed::Embedding::spread`]), plus the core's surface below.
//! The approach damping is left out (backward Euler damps the contact's own oscillation). The
//! tool receives minus the sum of the point forces at the end of the step; on a body with no
//! fixed node, minus what the step gave the core (see [`super::tick`](mod@super::tick) step 5:
//! the minimisation's residual included, so that linear momentum stays exact).
//!
//! # The core's surface: a wall the tool cannot pass
//! The core's surface meets the tool as a surface, not as its nodes: the point of the core's
//! faces within reach nearest the tool's centre, `p` (with barycentric weights `w` on its face),
//! at the signed distance `s` (positive outside the surface, negative beneath it: the side is told
//! by the solid angle the core's faces subtend at the centre, [`CoreContact::centre_is_beneath`]),
//! has the depth `R - s` and the energy `k_core (R - s)^2 / 2`, [`super::SimOptions::core_contact_stiffness`].
//! Its force on the face's nodes is `k_core (R - s) w_a u`, `u` the unit vector from the centre
//! to `p` (reversed when the centre is beneath the surface): the exact gradient (the closest point's
//! own motion drops out of `d|c - p|`, as it is the minimiser).
//!
//! Why (measured 2026-11-27, ninth session, `examples/press_sweep.rs` with `HOLD_MM=25`: the tool
//! pressed 25 mm in at 50 mm/s): the core's nodes alone, at the skin's 60 N/m a point, let the
//! tool through the organ. A point sphere penalty gives at most `k R = 0.3 N` before the
//! tool's centre passes the point, and the coarse core's nodes are farther apart than the tool
//! is wide: on the paper's ellipsoids beside the held base, the force rose to 0.69 N at 6 mm,
//! turned to pull the tool in (-0.47 N at 7.45 mm) and was zero past 11 mm, the tool through the
//! wall; on the Rodero ventricle, 2.75 N fell to zero at one point and 2.98 N to a pull at
//! another. The surface's nearest point cannot be passed between nodes, the sign keeps pushing
//! the tool out even from beneath a face, and the stiffness is the core's own (in the implicit
//! step, no sub-step bound applies): 10 times the tissue's under the sphere (Hertz, `~E* R`,
//! 180 N/m for the myocardium and a 5 mm sphere), 2 mm of penetration at 4 N.
//!
//! Limits, past what a device renders (measured with the tool driven by position, 25 mm in): the
//! side is taken only where the centre is within a radius of the surface at the tick's start, so
//! a centre pushed more than a radius beneath (`2 k R` = 20 N at the default) loses the contact;
//! and the coarse core crushed under 7-20 N can fold through itself, where no side is defined (on
//! Rodero at 3/5 of the height, 2.39 rad: 7.4 -> 13.2 N in a tick at 6.7 mm of travel, the
//! surface's winding changing 1.5 mm from it). Up to 5 N the 24-point sweeps of the Rodero
//! ventricle and the ellipsoids change the force by at most 0.27 N a tick (BENCHMARKS.md, "The
//! hybrid model under a hand's worst and a hard press").

use super::sim::Sim;
use super::tool::PointContact;
use crate::integrate::CorePotential;
use crate::math::Vec3;
use crate::mesh::winding_number;
use crate::spatial::closest_on_triangle;

/// Default tool stiffness against the core's surface \[N/m\] (see the module docs).
pub const CORE_CONTACT_STIFFNESS: f64 = 2000.0;

/// The tool at `centre` against the skin vertices `skin` (at their ties) and the core's surface.
pub struct CoreContact<'a> {
    /// The compiled simulation (its tool's radius and stiffness, skin ties, core surface).
    pub sim: &'a Sim,
    /// The tool's centre \[m\], world frame.
    pub centre: Vec3,
    /// Skin vertices that may touch (indices into the outer surface).
    pub skin: &'a [usize],
    /// Core faces that may touch (indices into the model's `core_faces`): the tool meets their
    /// point nearest its centre (see the module docs).
    pub core: &'a [usize],
    /// Per skin vertex, a constant offset \[m\] off its tie, times `lift_scale` (a shed shell's
    /// skin fading back to its ties; zeros: none).
    pub lift: &'a [Vec3],
    pub lift_scale: f64,
    /// The tool's centre is beneath the core's surface ([`CoreContact::centre_is_beneath`] at the
    /// tick's start): the side of the surface's signed distance, fixed over the step.
    pub beneath: bool,
}

/// The forces a [`CoreContact`] gave at the end of a step.
#[derive(Debug, Clone, Copy, Default)]
pub struct CoreContactSum {
    /// Sum of the forces on the tissue \[N\] (the tool receives the opposite).
    pub force: Vec3,
    /// Skin vertices in contact, and whether the core's surface is (0 or 1: the tool meets it at
    /// one point, see the module docs).
    pub skin_contacts: usize,
    pub core_contacts: usize,
    /// Deepest penetration \[m\].
    pub max_depth: f64,
}

impl CoreContact<'_> {
    /// Whether `centre` \[m\] is beneath the core's surface at core positions `x`: the core's
    /// faces' generalised winding number there ([`crate::mesh::winding_number`]) past 1/2: it changes only where the centre crosses the surface, and a fold of
    /// a crushed core, seen from both sides, cancels in it. Taken once a tick (300 faces on the
    /// Rodero ventricle's core, ~10 us) and fixed over the step, whose minimisation then sees a
    /// smooth energy: within a tick the tool moves less than a millimetre, and where it crosses
    /// the surface the two sides' depths `R - d` and `R + d` meet.
    ///
    /// Why not a local normal (measured on the Rodero ventricle pressed 25 mm in at 3/5 of its
    /// height, 2.39 rad, `examples/press_sweep.rs`): the nearest face's normal, and the nearest
    /// point's angle-weighted pseudonormal (Baerentzen and Aanaes 2005), turned over with the
    /// crushed core's faces and flipped the side with the centre millimetres from the surface
    /// (the force by `2 k d`, 4.5 N, every few ticks); the pseudonormal with a cosine threshold
    /// lost the side past an edge (18.6 N, then no contact); the solid angle of the faces within
    /// reach alone switched sides 2 mm beneath the surface (7.3 -> 13.0 N in a tick).
    pub fn centre_is_beneath(sim: &Sim, x: &[Vec3], centre: &Vec3) -> bool {
        winding_number(x, &sim.hybrid.core_faces, centre) > 0.5
    }

    /// Visit every skin vertex in contact at core positions `x`: `(vertex, contact)`, the
    /// contact being the tool's penalty at rest ([`super::Tool::contact`] with no velocities:
    /// the damping is left out, see the module docs).
    fn each_skin(&self, x: &[Vec3], mut visit: impl FnMut(usize, PointContact)) {
        let tool = &self.sim.tool;
        let at_rest = Vec3::zeros();
        for &v in self.skin {
            let p = self.sim.skin.position(v, x) + self.lift_scale * self.lift[v];
            if let Some(c) = tool.sample(self.sim.skin_area[v]).contact(&self.centre, &at_rest, &p, &at_rest) {
                visit(v, c);
            }
        }
    }

    /// The core's surface against the tool at core positions `x`: the face of [`Self::core`]
    /// nearest the centre, the barycentric weights of its nearest point, and the contact there
    /// (module docs); `None` outside contact.
    pub fn surface(&self, x: &[Vec3]) -> Option<(usize, [f64; 3], PointContact)> {
        let faces = &self.sim.hybrid.core_faces;
        let mut best: Option<(f64, usize, Vec3, [f64; 3])> = None;
        for &t in self.core {
            let [a, b, c] = faces[t];
            let (p, w) = closest_on_triangle(&self.centre, &x[a], &x[b], &x[c]);
            let d2 = (p - self.centre).norm_squared();
            if best.is_none_or(|(b2, ..)| d2 < b2) {
                best = Some((d2, t, p, w));
            }
        }
        let (d2, t, p, w) = best?;
        // The signed distance: negative beneath the surface.
        let s = if self.beneath { -d2.sqrt() } else { d2.sqrt() };
        let depth = self.sim.options.tool.radius - s;
        if !(depth > 0.0 && depth.is_finite()) {
            return None;
        }
        // From the centre to the point (reversed beneath the surface); on it, into the face.
        let dir = if s != 0.0 {
            (p - self.centre) / s
        } else {
            let [a, b, c] = faces[t];
            -(x[b] - x[a]).cross(&(x[c] - x[a])).try_normalize(0.0)?
        };
        let k = self.sim.options.core_contact_stiffness;
        Some((t, w, PointContact { depth, normal: dir, force: k * depth * dir, energy: 0.5 * k * depth * depth }))
    }

    /// The contact's forces at core positions `x` (the end of the step).
    pub fn sum(&self, x: &[Vec3]) -> CoreContactSum {
        let mut s = CoreContactSum::default();
        self.each_skin(x, |_, c| {
            s.force += c.force;
            s.skin_contacts += 1;
            s.max_depth = s.max_depth.max(c.depth);
        });
        if let Some((_, _, c)) = self.surface(x) {
            s.force += c.force;
            s.core_contacts = 1;
            s.max_depth = s.max_depth.max(c.depth);
        }
        s
    }
}

impl CorePotential for CoreContact<'_> {
    fn energy_forces(&self, x: &[Vec3], f: &mut [Vec3]) -> f64 {
        let mut u = 0.0;
        self.each_skin(x, |v, c| {
            u += c.energy;
            self.sim.skin.spread(v, c.force, x, f);
        });
        if let Some((t, w, c)) = self.surface(x) {
            u += c.energy;
            for (&a, &w) in self.sim.hybrid.core_faces[t].iter().zip(&w) {
                f[a] += w * c.force;
            }
        }
        u
    }
}
