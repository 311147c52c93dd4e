//! Divergence caught when it starts, not at overflow (issue 15, item 4).
//!
//! A step that goes unstable (an explicit scheme past its stable step, the rest-linearised
//! backward Euler under a firm press, a shell under-stepped by a sub-step cap) does not turn
//! non-finite at once: its fastest mode grows by a constant factor a step, and the state stays
//! finite, and wrong, for tens to thousands of steps before it overflows. Every step
//! ([`crate::step`], the particle step, so the hybrid tick through both) therefore also checks a
//! physical bound on speed, allocation-free: the FEM step once a step, in one pass over the
//! nodes; the particle step every sub-step, fused into the sweep that updates the velocities
//! (an under-stepped shell went from 3 wave speeds to overflow within one 1 ms tick of 9
//! sub-steps: a check at the tick's end would only ever have seen the overflow). A node whose
//! speed relative to its body's mass-weighted mean velocity (the particle step: the free active
//! particles' mean at the step's start) is over
//!
//! `v_max = `[`SPEED_BOUND_WAVE_SPEEDS`]` * c_p`, with `c_p = sqrt((lambda + 2 mu) / rho)` the
//! material's P-wave speed \[m/s\] ([`crate::Material::wave_speed`]),
//!
//! makes the step fail as a non-finite one does: the state is restored to the start of the step
//! and [`crate::StepError::Diverging`] names the node, its speed and the bound.
//!
//! **Why this value.** In an elastic solid a material point moves relative to its neighbours at
//! `v = c * strain` (a plane wave; the same order in a vibrating or recoiling body), so tissue
//! that stays within a strain of 1 (100%) moves at most `c_p` relative to the body; the mean is
//! taken out so that a free body's translation (falling under gravity, pushed as a whole) is
//! never mistaken for divergence. The factor 50 leaves room for what is legitimate but local:
//! a point load's singular strain (a node under 5 N on a 1 kPa wall recoils at many times its
//! strain-1 speed when released) and the shell's local modes under a deep press
//! (`runtime::stability`). Measured on the suites that exercise the hardest legitimate
//! motion (tests/stability_sweep.rs: E 1 kPa-1 MPa, dt up to 4 ms, 5 N point presses released at
//! once; tests/runtime_hand.rs: 15 mm presses, a press toward 2 N, jabs and 0.5 m/s slides on
//! every shipped model; tests/runtime.rs, tests/dynamics.rs' stable runs), the largest relative
//! speed was 14.8 `c_p` in the sweep (a released 5 N point load) and 2.7 `c_p` in the hybrid
//! presses (measured 2026-11-26): the bound is 3.4 times over the first and 18 times over the
//! second. A diverging mode grows geometrically, so a bound 50 times over the
//! legitimate scale costs only `ln(50) / ln(growth)` steps over a tight one, against the
//! `~ln(1e308)` of waiting for overflow: a slow divergence (growth 1.5 a step) is caught ~10 steps
//! after it passes `c_p`, where overflow took ~1700.
//!
//! Not caught: a rigid spin faster than `v_max / r` (thousands of rad/s for soft tissue: not a
//! motion palpate simulates), and a divergence that stays under the bound (then it is bounded).

use crate::material::Material;
use crate::math::Vec3;

/// The speed bound in P-wave speeds (see the module).
pub const SPEED_BOUND_WAVE_SPEEDS: f64 = 50.0;

/// The speed bound \[m/s\] of a body of `material`: [`SPEED_BOUND_WAVE_SPEEDS`] times its P-wave speed.
pub fn speed_bound(material: &Material) -> f64 {
    SPEED_BOUND_WAVE_SPEEDS * material.wave_speed()
}

/// The fastest of `nodes` relative to their mass-weighted mean velocity, when its speed is over
/// `bound` \[m/s\]: `(node, speed)`. One pass for the mean, one for the speeds; no allocation.
pub(crate) fn over_bound<I>(v: &[Vec3], mass: &[f64], nodes: I, bound: f64) -> Option<(usize, f64)>
where
    I: Iterator<Item = usize> + Clone,
{
    let (mut p, mut m) = (Vec3::zeros(), 0.0);
    for i in nodes.clone() {
        p += mass[i] * v[i];
        m += mass[i];
    }
    let mean = if m > 0.0 { p / m } else { Vec3::zeros() };
    let (mut node, mut top) = (usize::MAX, 0.0f64);
    for i in nodes {
        let s2 = (v[i] - mean).norm_squared();
        if s2 > top {
            (node, top) = (i, s2);
        }
    }
    (top > bound * bound).then(|| (node, top.sqrt()))
}
