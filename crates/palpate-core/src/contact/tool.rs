//! The tool: a rigid sphere whose centre the caller sets each tick, and its penalty contact with
//! points (active particles, skin vertices).
//!
//! # Penalty, not constraints
//! A point at `x` inside the sphere of centre `c` and radius `R` has the depth
//! `d = R - |x - c| > 0` and the outward normal `n = (x - c) / |x - c|`; the contact is the
//! potential `U = k d^2 / 2`, whose force on the point is `-dU/dx = k d n`, plus a damping term
//! `c_d max(0, -(v - v_tool) . n) n` that resists approach only (it is zero while the point
//! separates, so the normal force `k d + ...` is never negative: the tool never pulls). The tool
//! receives the equal and opposite force.
//!
//! Why penalty rather than constraints (the haptic choice):
//! - **Smooth in the tool position.** The force is a continuous function of the tool centre
//!   (`k d`, with `d` continuous); a constraint's force is a Lagrange multiplier that jumps when
//!   the active set of constrained points changes (a point touching or leaving), and a haptic
//!   device renders every jump as a buzz.
//! - **Bounded rendered stiffness.** The stiffness the device must render is the tissue's in
//!   series with the contact springs, `1 / (1 / k_tissue + 1 / (n k))` with `n` points in
//!   contact: never above `n k`, so `k` bounds what the device must render (a constraint is an
//!   infinitely stiff spring in that series; the device then renders the tissue's stiffness
//!   plus whatever the solver's tolerance makes of it).
//! - **Explicit and local.** The particles are stepped explicitly (Verlet sub-steps); a penalty
//!   is one more force per point, allocation-free, with a known stability limit (below), while
//!   constraints need a projection or a solve coupled across the contact set every sub-step.
//!
//! The cost is a small interpenetration, `d = f / (n k)` at force `f` (on the paper's ellipsoids
//! 0.14-0.2 mm at 2-5 mm of travel with the default, below).
//!
//! # Per unit area: the runtime's contact ([`AreaTool`])
//! The hybrid runtime gives each skin vertex the penalty of the skin area it carries (a third of
//! its outer triangles' rest areas): `k_v = k_a A_v` with `k_a` \[N/m^3\] per unit area, default
//! [`AreaTool::default_stiffness`] `= 12 E* / min(R, 4 h)` with `h` the lattice spacing (the
//! full-FEM body's in the haptics crate too, with `min(R, 4 h) = R`).
//! A penalty per point made the contact as stiff as the skin was fine. Measured on the paper's
//! ellipsoids (5 mm sphere, 2 mm of travel, 1.15 mm lattice), the outer surface at 1,026 / 4,098
//! / 16,386 vertices (2026-12-07, `python/tests/test_validate.py`): per unit area the force was
//! 0.088 / 0.092 / 0.090 N and the tool sank 0.31 / 0.16 / 0.17 mm into the skin; with 60 N/m a
//! vertex (before), at 2,050 / 4,098 / 16,386 vertices, 0.062 / 0.084 / 0.091 N and 0.88-1.60 /
//! 0.39-0.46 / 0.16-0.19 mm. What is left of the force's spread is the shell's own geometry (a
//! coarser outer polyhedron is a thinner wall). On the Rodero skin (0.72 mm^2 a vertex) the
//! default is the 62 N/m a vertex it had; on the ellipsoids' (2.8 mm^2) four times that.
//!
//! A vertex carries at most [`crate::runtime::sim::SKIN_AREA_CAP_SPACINGS2`] squared lattice spacings:
//! on a skin much coarser than the lattice (the tests' 66-vertex ellipsoid, 230 mm^2 a vertex on
//! a 4 mm lattice) one vertex, carried by the few particles under it, met the sphere with 25 kN/m
//! and bounced off it (1.7 N one tick, 0 the next three). Capped, such a skin's contact is softer
//! per area than asked (the 1,026-vertex ellipsoid above: 11 mm^2 a vertex capped at 3.3, the
//! tool sank 0.31 mm where it sinks 0.16 into the finer skins; its force 5% below theirs), and a
//! skin that the cap binds everywhere is a point contact again, `k_a` times the cap a vertex.

//! # Stability and fidelity
//! Two bounds meet:
//! - **Stability** of an explicit sub-step `h` on the lightest contacted particle of mass `m`:
//!   central differences are stable while the largest `omega^2 = k_total / m` satisfies
//!   `omega h < 2`. The particle's internal forces already take `omega_int h <= 2 S`
//!   (`S` = [`STABILITY_SAFETY`] = 0.9: the particle body's sub-step is that fraction of its
//!   critical step), so in the worst case (the stiffest internal mode at the contacted particle,
//!   along the normal) the contact spring may add `k <= (4 - (2 S)^2) m / h^2 = 0.76 m / h^2`:
//!   [`Tool::stiffness_for`]. The runtime does not bound the contact by it: its sub-step count
//!   counts the contact's share of each particle ([`crate::runtime::stability`]), and the contact is cheap
//!   there (on the Rodero ventricle 60 / 120 / 240 / 480 N/m a vertex took 12.0 / 12.7 / 13.9 /
//!   16.2 sub-steps a tick; on the ellipsoids 60 / 240 / 960 N/m 16.0 / 17.1 / 19.9).
//! - **Fidelity**: the contact springs in series with the tissue should be stiffer than the
//!   tissue under the sphere, `k_tissue ~ 2 E* a` (Hertz: `E* = E / (1 - nu^2)`, contact radius
//!   `a = sqrt(R d)`), about `E* R` at `d ~ R / 4`; per unit area, `E* / (1.7 a)`
//!   ([`AreaTool::default_stiffness`]).

use crate::material::Material;
use crate::math::Vec3;
use crate::meshfree::STABILITY_SAFETY;

/// Default tool radius \[m\] (the 5 mm sphere).
pub const DEFAULT_RADIUS: f64 = 5.0e-3;
/// Default penalty stiffness of [`Tool::default`], a point penalty \[N/m\] (the runtime's is per
/// unit area: [`AreaTool`]).
pub const DEFAULT_STIFFNESS: f64 = 60.0;
/// Default contact damping per contact point \[N s/m\]: 0.15 of the critical damping
/// `2 sqrt(k m)` of [`DEFAULT_STIFFNESS`] on a 7.2e-7 kg particle (`2 sqrt(60 * 7.2e-7) ~ 0.013`).
///
/// Why not more (it was 0.0065, half critical, until 2026-11-26): the damper is explicit, so its
/// rate `c / m` over the particles under the tool adds to the shell's damping in the sub-step
/// count ([`crate::runtime::stability`]), and on the Rodero ventricle (a fine skin: ~4.5 skin vertices a
/// surface particle) it was as large as the tissue's own: 11.7 sub-steps a contact tick with
/// 0.0065 against 11.0 with 0.002 and 10.8 with none (5 mm tool, 4 mm press and 10 mm slide,
/// `examples/tick_profile.rs` with `TOOL_C`). What it buys is small and saturates early: with
/// the paper's damped tissue the force is the same to 3 digits with any of the three and as
/// smooth (tick-to-tick jumps: p99 2.5%, max 8.3-8.5%); with undamped tissue, none gives a
/// rougher force (max jump 13%, mean second difference +53%), 0.002 nearly the half-critical
/// one's (8.6% vs 8.5%, +13%).
pub const DEFAULT_DAMPING: f64 = 0.002;

/// A rigid sphere tool: radius \[m\], penalty stiffness \[N/m\] and approach damping \[N s/m\], each
/// per contact point. Its centre and velocity are the caller's, per tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tool {
    /// Sphere radius \[m\].
    pub radius: f64,
    /// Penalty stiffness per contact point \[N/m\].
    pub stiffness: f64,
    /// Damping against approach per contact point \[N s/m\].
    pub damping: f64,
}

impl Default for Tool {
    fn default() -> Self {
        Tool { radius: DEFAULT_RADIUS, stiffness: DEFAULT_STIFFNESS, damping: DEFAULT_DAMPING }
    }
}

/// The contact of one point with the tool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointContact {
    /// Depth `R - |x - c|` \[m\], > 0.
    pub depth: f64,
    /// Unit normal from the centre to the point.
    pub normal: Vec3,
    /// Force on the point \[N\] (the tool receives its opposite); along `normal`, never against it.
    pub force: Vec3,
    /// Penalty energy `k d^2 / 2` \[J\].
    pub energy: f64,
}

/// Sums over many points ([`Tool::apply`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactSum {
    /// Force on the tool \[N\] (minus the sum of the forces on the points).
    pub force_on_tool: Vec3,
    /// Points in contact.
    pub count: usize,
    /// Total penalty energy \[J\].
    pub energy: f64,
    /// Deepest depth \[m\] (0 without contact).
    pub max_depth: f64,
}

impl Tool {
    /// The largest penalty stiffness \[N/m\] an explicit sub-step `substep` \[s\] keeps stable on
    /// a particle of mass `mass` \[kg\] whose internal forces already use the sub-step's budget
    /// up to [`STABILITY_SAFETY`]: `(4 - (2 S)^2) mass / substep^2` (0.76 m / h^2; 0 for
    /// non-positive or non-finite input). See the module docs.
    pub fn stiffness_for(mass: f64, substep: f64) -> f64 {
        let k = (4.0 - (2.0 * STABILITY_SAFETY).powi(2)) * mass / (substep * substep);
        if mass > 0.0 && substep > 0.0 && k.is_finite() {
            k
        } else {
            0.0
        }
    }

    /// Damping \[N s/m\] of ratio `ratio` (1: critical) for stiffness `k` \[N/m\] on mass `mass`
    /// \[kg\]: `2 ratio sqrt(k m)` (0 for negative or non-finite input).
    pub fn damping_for(stiffness: f64, mass: f64, ratio: f64) -> f64 {
        let c = 2.0 * ratio * (stiffness * mass).sqrt();
        if c.is_finite() && c > 0.0 {
            c
        } else {
            0.0
        }
    }

    /// The penalty potential `k d^2 / 2` \[J\] of a point at `x` \[m\] against the tool centred at
    /// `centre` \[m\] (0 outside contact or for non-finite input).
    pub fn potential(&self, centre: &Vec3, x: &Vec3) -> f64 {
        let d = self.radius - (x - centre).norm();
        if d > 0.0 && d.is_finite() {
            0.5 * self.stiffness * d * d
        } else {
            0.0
        }
    }

    /// The contact of a point at `x` \[m\] with velocity `v` \[m/s\] against the tool at `centre`
    /// \[m\] moving with `tool_velocity` \[m/s\]; `None` outside contact, at the exact centre (no
    /// normal) or for non-finite input.
    #[inline]
    pub fn contact(&self, centre: &Vec3, tool_velocity: &Vec3, x: &Vec3, v: &Vec3) -> Option<PointContact> {
        let r = x - centre;
        let dist = r.norm();
        let depth = self.radius - dist;
        if !(depth > 0.0 && dist > 0.0 && depth.is_finite()) {
            return None;
        }
        let normal = r / dist;
        let approach = -(v - tool_velocity).dot(&normal);
        let damping = if approach > 0.0 && approach.is_finite() { self.damping * approach } else { 0.0 };
        // Both terms are >= 0: the normal force never pulls.
        let fn_ = self.stiffness * depth + damping;
        Some(PointContact { depth, normal, force: fn_ * normal, energy: 0.5 * self.stiffness * depth * depth })
    }

    /// Add the contact forces of the points `which` (indices into `x`, `v` and `forces`; out of
    /// range ones skipped) to `forces` \[N\], and return their sums (the force on the tool is
    /// the opposite of what the points received). Allocation-free.
    pub fn apply(&self, centre: &Vec3, tool_velocity: &Vec3, x: &[Vec3], v: &[Vec3], which: &[usize], forces: &mut [Vec3]) -> ContactSum {
        let mut sum = ContactSum::default();
        let n = x.len().min(v.len()).min(forces.len());
        for &i in which {
            if i >= n {
                continue;
            }
            if let Some(c) = self.contact(centre, tool_velocity, &x[i], &v[i]) {
                forces[i] += c.force;
                sum.force_on_tool -= c.force;
                sum.count += 1;
                sum.energy += c.energy;
                sum.max_depth = sum.max_depth.max(c.depth);
            }
        }
        sum
    }
}

/// The default penalty per unit area in units of `E* / R` ([`AreaTool::default_stiffness`]).
pub const AREA_STIFFNESS_PER_E_OVER_R: f64 = 12.0;

/// The smallest contact the default penalty is stiff for, as a diameter in lattice spacings
/// ([`AreaTool::default_stiffness`]: `min(R, 4 h)`; a contact radius of two spacings).
pub const CONTACT_SPACINGS: f64 = 4.0;

/// Default approach damping per unit of skin area \[N s/m^3\]: the 0.002 N s/m a skin vertex of
/// the per-point contact had (see [`DEFAULT_DAMPING`] for why so little) over the Rodero
/// ventricle's 0.72 mm^2 a vertex.
pub const DEFAULT_AREA_DAMPING: f64 = 2.8e3;

/// The tool's penalty per unit of the surface's rest area: radius \[m\], stiffness \[N/m^3\] and
/// approach damping \[N s/m^3\]. A point carrying the area `A` \[m^2\] meets the tool as the
/// point penalty [`AreaTool::sample`] `= Tool { k A, c A }`: the contact's stiffness over a patch
/// is then `k` times the patch's area whatever the tessellation of the surface (a penalty per
/// point makes a skin twice as fine twice as stiff: measured on the paper's ellipsoids with
/// 2,050 / 4,098 / 16,386 skin vertices at 60 N/m each, the 5 mm sphere sank 0.9-1.6 / 0.39-0.46
/// / 0.16-0.19 mm into the skin at 2-6 mm of travel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaTool {
    /// Sphere radius \[m\].
    pub radius: f64,
    /// Penalty stiffness per unit area \[N/m^3\].
    pub stiffness: f64,
    /// Approach damping per unit area \[N s/m^3\].
    pub damping: f64,
}

impl AreaTool {
    /// The point contact of a point carrying `area` \[m^2\].
    #[inline]
    pub fn sample(&self, area: f64) -> Tool {
        Tool { radius: self.radius, stiffness: self.stiffness * area, damping: self.damping * area }
    }

    /// The default penalty per unit area \[N/m^3\] for a tissue of `material` under a sphere of
    /// `radius` \[m\] on a model that resolves contacts down to a radius of two `spacing`s \[m\]:
    /// `12 E* / min(R, 4 h)`, `E* = E / (1 - nu^2)`, ten times the tissue's own stiffness per
    /// unit area under the smallest contact the model resolves. Hertz: a pressure `p` on a disc
    /// of radius `a` of an elastic half-space sinks it by `16 p a / (3 pi E*) ~ 1.7 p a / E*` on
    /// average, a stiffness per unit area of `E* / (1.7 a)`, larger the smaller the contact. The
    /// smallest contact that matters is a quarter-radius press (`a = R / 2`: `1.18 E* / R`) or,
    /// under a large sphere, two lattice spacings (below that the lattice cannot shape the dent):
    /// ten times it, the contact adds at most ~10% compliance in series with the tissue.
    ///
    /// Why the spacing (2026-12-07): with `12 E* / R` alone a 15 mm sphere's contact was 4x the
    /// tissue's at a shallow press, and its compliance blunted the indenter: on an 80 x 80 x 40 mm
    /// hybrid slab (`bench/hybrid_slab.py`, 1.09 mm lattice) the force at 0.64 / 1.44 mm of
    /// indentation was +34 / +25% over Hertz with 2.9e7 N/m^3, +20 / +19% with 1.2e8 and +16 / +18%
    /// with 4e8 (a converged FEM of the same slab, 129k tets: +12 / +8%, converging toward Hertz).
    /// Myocardium (30 kPa, `nu = 0.4`) under the 5 mm sphere: 8.6e7 N/m^3 on the Rodero model
    /// (1.63 mm lattice: the radius sets it; 0.72 mm^2 a skin vertex, 62 N/m a vertex, the per-point
    /// default it replaces), 9.3e7 on the paper's ellipsoids (1.15 mm); under a 15 mm sphere 6.6e7
    /// and 9.3e7 (the spacing sets it). `spacing` infinite: `12 E* / R`.
    pub fn default_stiffness(material: &Material, radius: f64, spacing: f64) -> f64 {
        let nu = material.poisson();
        AREA_STIFFNESS_PER_E_OVER_R * material.young() / (1.0 - nu * nu) / radius.min(CONTACT_SPACINGS * spacing)
    }
}

/// The tool of a hybrid simulation as its options give it ([`crate::runtime::SimOptions::tool`]):
/// resolved against the material by [`ToolOptions::resolve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolOptions {
    /// Sphere radius \[m\] (default [`DEFAULT_RADIUS`], 5 mm).
    pub radius: f64,
    /// Penalty stiffness per unit of skin area \[N/m^3\]; `None` (default):
    /// [`AreaTool::default_stiffness`] of the material, the radius and the model's spacing.
    pub area_stiffness: Option<f64>,
    /// Approach damping per unit of skin area \[N s/m^3\] (default [`DEFAULT_AREA_DAMPING`]).
    pub area_damping: f64,
}

impl Default for ToolOptions {
    fn default() -> Self {
        ToolOptions { radius: DEFAULT_RADIUS, area_stiffness: None, area_damping: DEFAULT_AREA_DAMPING }
    }
}

impl ToolOptions {
    /// The tool with its stiffness resolved for `material` on a lattice of `spacing` \[m\].
    pub fn resolve(&self, material: &Material, spacing: f64) -> AreaTool {
        let stiffness = self.area_stiffness.unwrap_or_else(|| AreaTool::default_stiffness(material, self.radius, spacing));
        AreaTool { radius: self.radius, stiffness, damping: self.area_damping }
    }
}
