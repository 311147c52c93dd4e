//! The rigid sphere tool against a tet mesh's boundary **surface** (its triangles), for
//! `palpate_haptics::FemPhysics`: a penalty per unit area, integrated by sample points fixed on the
//! triangles, each sample's force spread to its triangle's nodes.
//!
//! # Why the surface, not the nodes
//! A penalty on the boundary nodes alone feels nothing between nodes: on a mesh whose boundary
//! node spacing is comparable to the tool (the protocol meshes, `ellipsoid_192`: 15-25 mm
//! between nodes under a 5 mm sphere) a press between nodes touches no node, a press on a node
//! pushes the node sideways until it slides off the sphere, and a slide bumps from node to node.
//! Here the contact is the potential
//!
//! `U = sum_s k_a A_s d_s^2 / 2`,  `d_s = max(0, R - |x_s - c|)`,  `x_s = sum_i b_si x_i`,
//!
//! over sample points `s` fixed in the boundary triangles by barycentric coordinates `b_si`, each
//! with its share `A_s` of its triangle's rest area: a quadrature of `k_a / 2 int d^2 dA` over
//! the surface, `k_a` \[N/m^3\] the stiffness per unit area. A triangle is cut into `n^2` equal
//! sub-triangles (`n` = its longest rest edge over the spacing, rounded up) and sampled at their
//! centroids, so samples are at most [`SAMPLE_SPACING`] `R` apart: a sphere pressed `d` deep
//! meets a patch of radius `sqrt(2 R d)` and, from 1 mm deep, a dozen samples or more wherever
//! it is (the nodes do not matter).
//!
//! Each sample's penalty is [`crate::contact::Tool::contact`] (the hybrid runtime's point contact, with the
//! stiffness `k_a A_s` and damping `c_a A_s`); its force goes to the triangle's nodes with the
//! sample's barycentric weights. That spread is the transpose of the interpolation `x_s = sum_i
//! b_si x_i`, so the nodal forces are exactly `-dU/dx_i` (the damping aside), the sample forces
//! summed over nodes are the sample forces (`sum_i b_si = 1`) and no momentum is lost. The rest
//! areas make the quadrature Lagrangian: the stiffness a node can see never depends on how the
//! surface is stretched, which is what makes the stability bound below hold at every state.
//!
//! # Stability: a Gershgorin bound per node
//! The contact is explicit (held over an implicit step, see `palpate_haptics::FemPhysics`); it is stable
//! while `omega^2 dt^2` of its stiffness on the lumped masses stays below the limit on every
//! node. The contact Hessian's positive part is `sum_s k_a A_s (b_s b_s^T) (x) (n_s n_s^T)`
//! (the curvature term `-k d / r (I - n n^T)` only lowers it), whose Gershgorin row sum at node
//! `a` is at most `k_a sum_s A_s b_sa sum_j b_sj = k_a G_a`, `G_a = sum_s A_s b_sa` over the
//! node's samples ([`SurfaceContact::area_shares`], a third of its triangles' rest area). So
//! `omega_max^2 <= k_a max_a G_a / m_a` over the free nodes, at every state (rest areas: the
//! bound never depends on the deformation) and wherever the tool is.
//!
//! Over every sample of a node's triangles that bound is far too low on coarse meshes: a node's
//! star of triangles is several times the tool's patch (ellipsoid_192: ~10x; the sphere then
//! sank through a 15 mm press at 0.04 N). Only the samples the tool can touch count: those in
//! a ball of radius `R` about its centre. Two bounds together:
//! - **one stiffness for the surface** (set once, [`SurfaceContact::area_shares`] and the
//!   caller): `G_a <= min(sum of all its samples, pi (R + delta)^2)`, the second the area of a
//!   flat surface within reach, over the lightest free node. It does not depend on where the
//!   tool is, so the feel does not depend on where the nodes are;
//! - **the samples actually in reach, each tick** ([`SurfaceContact::reach_mass_per_area`]): the
//!   sum over the samples within `R + delta` of the centre (`delta` = [`REACH_MARGIN`] `R`),
//!   weighted 1 within `R` and linearly less to 0 at `R + delta`. Every sample in contact has
//!   weight 1, so it bounds the contact's row sum at every state; the ramp makes it continuous
//!   in the positions. It is the proven bound, and binds only where the surface within reach
//!   is more than a flat disc (a deep press wrapping the surface around the sphere).
//!
//! The contact takes the lower stiffness. Rejected: the per-tick bound alone. It is stiffer on
//! coarse meshes, but depends on where the tool is relative to the nodes: on a 15 mm slab it was
//! twice as stiff between nodes as on a node (the patch's load shared by three nodes or carried
//! by one), so a slide felt the nodes again, as a 1.7x swell of the force.
//!
//! # Cost
//! Each tick bounds every boundary triangle by the sphere through its centroid and farthest
//! node (at the current positions: exact, so no margin is needed against deformation) and looks
//! at the samples of the triangles that can reach the tool: one pass over the triangles (about
//! 30 flops each), and two over the samples of the few triangles near the tool. Nothing is
//! allocated.

pub use super::tool::AreaTool;
use super::tool::ContactSum;
use crate::error::ModelError;
use crate::math::Vec3;

/// Largest spacing of the contact samples, as a fraction of the tool's radius.
pub const SAMPLE_SPACING: f64 = 1.0 / 3.0;
/// The per-tick bound's reach beyond the sphere, as a fraction of its radius (module docs).
pub const REACH_MARGIN: f64 = 0.25;
/// Most contact samples [`SurfaceContact::new`] makes (24 bytes each): a tool far smaller than
/// the mesh's triangles is refused rather than sampled into gigabytes.
pub const MAX_SAMPLES: usize = 8_000_000;

/// The boundary triangles, their contact samples and the per-tick scratch (module docs).
#[derive(Debug, Clone)]
pub struct SurfaceContact {
    faces: Vec<[usize; 3]>,
    /// Samples of face `f`: `start[f]..start[f + 1]`.
    start: Vec<usize>,
    /// Rest area of each of face `f`'s samples \[m^2\].
    area: Vec<f64>,
    /// Barycentric coordinates of every sample.
    bary: Vec<[f64; 3]>,
    /// The radius the samples were spaced for \[m\].
    radius: f64,
    /// Per node: `G_a = sum_s A_s b_sa` \[m^2\] (the stability bound's row sum).
    share: Vec<f64>,
    /// Faces near the tool this tick (capacity: every face).
    near: Vec<usize>,
    /// Per node: the reach-weighted area of the per-tick bound (zero outside a tick).
    reach: Vec<f64>,
}

impl SurfaceContact {
    /// Samples `faces` (node triples into `points`, the rest positions \[m\]) for a sphere of
    /// `radius` \[m\] ([`SAMPLE_SPACING`]). Refuses a radius that would need more than
    /// [`MAX_SAMPLES`] samples.
    pub fn new(points: &[Vec3], faces: Vec<[usize; 3]>, radius: f64) -> Result<SurfaceContact, ModelError> {
        let h = SAMPLE_SPACING * radius;
        let cuts = |f: &[usize; 3]| {
            let p = f.map(|i| points[i]);
            let longest = (p[1] - p[0]).norm().max((p[2] - p[1]).norm()).max((p[0] - p[2]).norm());
            ((longest / h).ceil() as usize).max(1)
        };
        let total: f64 = faces.iter().map(|f| (cuts(f) as f64).powi(2)).sum();
        if total > MAX_SAMPLES as f64 {
            return Err(ModelError::Parameter {
                name: "tool radius",
                value: radius,
                reason: "too small for the mesh's boundary triangles: the surface contact would need more than 8 million samples (spaced R / 3)",
            });
        }
        let mut start = Vec::with_capacity(faces.len() + 1);
        let mut area = Vec::with_capacity(faces.len());
        let mut bary = Vec::with_capacity(total as usize);
        start.push(0);
        for f in &faces {
            let n = cuts(f);
            let p = f.map(|i| points[i]);
            area.push(0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm() / (n * n) as f64);
            let nf = n as f64;
            // Sub-triangle centroids: the n (n + 1) / 2 upright ones, then the n (n - 1) / 2
            // inverted ones, in (b1, b2).
            for (shift, count) in [(1.0 / 3.0, n), (2.0 / 3.0, n - 1)] {
                for i in 0..count {
                    for j in 0..count - i {
                        let (b1, b2) = ((i as f64 + shift) / nf, (j as f64 + shift) / nf);
                        bary.push([1.0 - b1 - b2, b1, b2]);
                    }
                }
            }
            start.push(bary.len());
        }
        let mut share = vec![0.0; points.len()];
        for (f, t) in faces.iter().enumerate() {
            for w in &bary[start[f]..start[f + 1]] {
                for k in 0..3 {
                    share[t[k]] += area[f] * w[k];
                }
            }
        }
        let near = Vec::with_capacity(faces.len());
        let reach = vec![0.0; points.len()];
        Ok(SurfaceContact { faces, start, area, bary, radius, share, near, reach })
    }

    /// The boundary triangles.
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    /// How many samples in all.
    pub fn n_samples(&self) -> usize {
        self.bary.len()
    }
    /// The radius the samples were spaced for \[m\].
    pub fn radius(&self) -> f64 {
        self.radius
    }
    /// Face `f`'s samples: barycentric coordinates, and the rest area each carries \[m^2\].
    pub fn samples(&self, f: usize) -> (&[[f64; 3]], f64) {
        (&self.bary[self.start[f]..self.start[f + 1]], self.area[f])
    }

    /// Finds the faces that can reach within `reach` \[m\] of `centre` (positions `x`, \[m\]): every
    /// face with a point that close is among them. The list is what the next
    /// [`SurfaceContact::apply`] looks at.
    pub fn find_near(&mut self, centre: &Vec3, x: &[Vec3], reach: f64) {
        self.near.clear();
        for (f, t) in self.faces.iter().enumerate() {
            let (a, b, c) = (x[t[0]], x[t[1]], x[t[2]]);
            let m = (a + b + c) / 3.0;
            let r2 = (a - m).norm_squared().max((b - m).norm_squared()).max((c - m).norm_squared());
            // |m - centre| < reach + r, without the root where the answer is plain.
            let d2 = (m - centre).norm_squared();
            if d2 < reach * reach + r2 || d2.sqrt() < reach + r2.sqrt() {
                self.near.push(f);
            }
        }
    }

    /// The faces [`SurfaceContact::find_near`] found.
    pub fn near(&self) -> &[usize] {
        &self.near
    }

    /// Per node, the rest area its samples carry weighted by their barycentric weight at it,
    /// `G_a = sum_s A_s b_sa` \[m^2\] (a third of its triangles' area): the contact of stiffness
    /// `k_a` per unit area has `omega^2 <= k_a G_a / m_a` on node `a` (module docs).
    pub fn area_shares(&self) -> &[f64] {
        &self.share
    }

    /// The lightest free node's mass per contact area in reach this tick, `min_a m_a / G_a`
    /// \[kg/m^2\] (infinite if no free node has a sample in reach): `G_a` sums `A_s b_sa` over
    /// the near faces' samples within `R + delta` of `centre` (`delta` = [`REACH_MARGIN`] `R`),
    /// weighted 1 within `R` and linearly less to 0 at `R + delta`, so it bounds the row sum of
    /// the samples in contact and is continuous in the tool's and nodes' positions (module
    /// docs). Call after [`SurfaceContact::find_near`] with a reach of at least `R + delta`.
    pub fn reach_mass_per_area(&mut self, radius: f64, centre: &Vec3, x: &[Vec3], masses: &[f64], fixed: &[bool]) -> f64 {
        let delta = REACH_MARGIN * radius;
        for &f in &self.near {
            let t = self.faces[f];
            for w in &self.bary[self.start[f]..self.start[f + 1]] {
                let r = (at(&t, w, x) - centre).norm();
                let weight = ((radius + delta - r) / delta).clamp(0.0, 1.0) * self.area[f];
                for k in 0..3 {
                    self.reach[t[k]] += weight * w[k];
                }
            }
        }
        let mut least = f64::INFINITY;
        for &f in &self.near {
            for i in self.faces[f] {
                let g = self.reach[i];
                if g > 0.0 {
                    if !fixed[i] {
                        least = least.min(masses[i] / g);
                    }
                    self.reach[i] = 0.0;
                }
            }
        }
        least
    }

    /// Adds the contact forces of `tool` centred at `centre` (moving at `tool_velocity`) on the
    /// near faces' samples, spread to their nodes, to `forces` \[N\] (positions `x`, velocities
    /// `v`); returns the sums (`force_on_tool`: minus the sum of the sample forces, equal to
    /// minus the sum of what the nodes received up to round-off; `palpate_haptics::FemPhysics` sums the
    /// nodes for an exact reaction). Call after [`SurfaceContact::find_near`] with a reach of at
    /// least `tool.radius`. Allocation-free.
    pub fn apply(&self, tool: &AreaTool, centre: &Vec3, tool_velocity: &Vec3, x: &[Vec3], v: &[Vec3], forces: &mut [Vec3]) -> ContactSum {
        let mut sum = ContactSum::default();
        for &f in &self.near {
            let t = self.faces[f];
            let point = tool.sample(self.area[f]);
            for w in &self.bary[self.start[f]..self.start[f + 1]] {
                let xs = at(&t, w, x);
                let vs = at(&t, w, v);
                if let Some(c) = point.contact(centre, tool_velocity, &xs, &vs) {
                    for k in 0..3 {
                        forces[t[k]] += c.force * w[k];
                    }
                    sum.force_on_tool -= c.force;
                    sum.count += 1;
                    sum.energy += c.energy;
                    sum.max_depth = sum.max_depth.max(c.depth);
                }
            }
        }
        sum
    }

    /// The penalty energy `sum_s k_a A_s d_s^2 / 2` \[J\] of `tool` at `centre` over every sample
    /// (no culling: the tests' reference).
    pub fn energy(&self, tool: &AreaTool, centre: &Vec3, x: &[Vec3]) -> f64 {
        let mut e = 0.0;
        for (f, t) in self.faces.iter().enumerate() {
            let point = tool.sample(self.area[f]);
            for w in &self.bary[self.start[f]..self.start[f + 1]] {
                e += point.potential(centre, &at(t, w, x));
            }
        }
        e
    }
}

/// The point of barycentric coordinates `w` in triangle `t` of the nodes `x` (positions or
/// velocities): where a sample sits, and the transpose of how its force is spread.
#[inline]
fn at(t: &[usize; 3], w: &[f64; 3], x: &[Vec3]) -> Vec3 {
    x[t[0]] * w[0] + x[t[1]] * w[1] + x[t[2]] * w[2]
}
