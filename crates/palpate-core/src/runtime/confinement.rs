//! Confinement (paper §6.1, Fig. 5): an elastic wall keeps the active particles inside the union
//! of their active regions.
//!
//! The shared voxel grid (`HybridModel::grid`) records, per voxel, the outer triangle its field
//! line reaches (`HybridModel::voxel_owner`, or `VOXEL_OUTSIDE` / `VOXEL_CORE`). The allowed set
//! `A` is the union of the voxels owned by active outer triangles (those whose count in
//! [`super::activation::Activation::triangle_counts`] is positive). A particle at `x` with
//! anchor `X` (its rest-embedded position, which the caller moves with the core) has the
//! potential `k_c max(0, dist(x, A) - dist(X, A))^2 / 2`, `dist` the Euclidean distance to the
//! nearest voxel cube of `A` (0 inside `A`); its force is `-k_c (d - s) (x - q) / d`, `q` the
//! nearest point of that cube, `d = |x - q|`, `s = dist(X, A)`: zero inside `A` and continuous
//! across its boundary (the wall is elastic: a particle may cross it by `f / k_c`). It is the
//! exact gradient of the potential wherever the nearest cube is unique. The slack `s` is zero
//! for almost every particle; it is there because ~7% of the particles of a lone active region
//! rest in a voxel that another outer triangle owns (measured on the synthetic ventricle: the
//! particles' triangles come from projecting to the outer surface, the voxels' from following
//! the field line, and the two disagree near triangle edges), and a wall that pushed them at
//! rest would jerk the force when their region enters.
//!
//! How this relates to the paper's B(p_s) and `HybridModel::region_field`: the paper embeds each
//! RV(p_s) in a voxel box B(p_s) and stores a gradient field pointing to the nearest boundary
//! voxel, applied to boundary particles and to those that cross a boundary voxel.
//! `region_field(s)` is that field computed offline for one region (labels and a unit gradient
//! to the nearest interior voxel, over the whole box: a few hundred voxels, but ~100 MB if stored
//! for every region of the Rodero model). Here the same direction is computed locally and only
//! where it is needed: for a particle outside `A`, a search of the voxels within `reach` voxels
//! (Chebyshev rings, stopping once no nearer voxel can exist) for the nearest active-owned voxel.
//! So no per-region box is stored, the field serves any union of regions (the paper's boxes are
//! per region; a union of overlapping boxes has no single field), and it has a potential, so the
//! wall conserves energy. Departures from the letter: (i) no force on particles inside `A`, also
//! in its boundary layer (the paper pushes boundary particles inward all the time: a constant
//! pressure with no rest state); (ii) the force grows with the distance outside (an elastic wall)
//! rather than being a unit gradient times a constant; (iii) the direction is to the nearest
//! allowed voxel (the paper's "nearest voxel in the boundary", since from outside the nearest
//! allowed voxel is a boundary one), where `region_field`'s gradient points to the nearest
//! *interior* voxel: the two differ where a region's voxels are thin or fragmented (near a base),
//! by 40 degrees on average on the synthetic ventricle (tests/runtime_parts.rs). A particle
//! with no allowed voxel within `reach` (far outside, or a region with no voxel) is pulled to
//! its anchor by the spring `k_c |x - X|^2 / 2` (a different potential: far outside, the wall's
//! field is not defined locally).

use crate::hybrid::{VoxelGrid, VOXEL_CORE};
use crate::math::Vec3;

/// Default reach of the search \[voxels\]: a particle up to ~2 voxels outside its region finds the
/// wall; farther ones fall back to their anchor.
pub const DEFAULT_REACH: usize = 3;
/// Default wall stiffness per particle \[N/m\]: twice the stiffness of one lattice cell of the
/// tissue (`E s`: 30 kPa x 0.9 mm = 27 N/m on the synthetic ventricle), so a particle pressed
/// outward by its neighbours' elastic forces crosses the wall by about a third of its own
/// displacement; and, like the tool's contact spring, inside the explicit sub-step's spare
/// stability budget `0.76 m / h^2` (63 N/m there: see [`super::tool`]). A particle pressed by
/// the tool against the wall feels both springs (`omega h ~ 1.2` for 60 + 60 N/m): with its
/// internal forces at their own limit too, that would exceed central differences' bound
/// (`sqrt(1.8^2 + 1.2^2) = 2.2 > 2`); surface particles, with fewer neighbours, are far below
/// that limit, but a tick that can press a particle against the wall should keep the sum of the
/// two within `Tool::stiffness_for(lightest mass, sub-step)`.
pub const DEFAULT_STIFFNESS: f64 = 60.0;
/// Largest reach the search takes \[voxels\] (a larger `reach` is capped).
pub const MAX_REACH: usize = 8;

/// The elastic wall: stiffness \[N/m\] and search reach \[voxels\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Confinement {
    /// Wall stiffness `k_c` \[N/m\] per particle.
    pub stiffness: f64,
    /// Chebyshev radius of the search for an allowed voxel \[voxels\].
    pub reach: usize,
}

/// Where a particle is with respect to the allowed set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// In a voxel owned by an active triangle: no force.
    Inside,
    /// Outside, but no farther than its anchor is: no force.
    Slack,
    /// Outside, farther than its anchor: pushed to the nearest allowed voxel within reach.
    Outside,
    /// Outside with no allowed voxel within reach: pulled to its anchor.
    Anchored,
    /// Non-finite position or anchor: no force.
    Invalid,
}

/// The wall's action on one particle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Push {
    /// Force on the particle \[N\].
    pub force: Vec3,
    /// Potential `k_c (dist - slack)^2 / 2` \[J\].
    pub energy: f64,
    /// Distance to the allowed set (for [`Placement::Anchored`]: to the anchor) \[m\].
    pub distance: f64,
    pub placement: Placement,
}

/// Sums over many particles ([`Confinement::apply`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ConfinementSum {
    /// Particles pushed (outside the allowed set).
    pub pushed: usize,
    /// Of those, pulled to their anchors.
    pub anchored: usize,
    /// Non-finite positions skipped.
    pub invalid: usize,
    /// Total potential \[J\].
    pub energy: f64,
    /// Largest distance outside \[m\].
    pub max_distance: f64,
}

/// Is voxel owner `o` an active outer triangle under the per-triangle counts `tri_count`?
#[inline]
fn allowed(o: u32, tri_count: &[u32]) -> bool {
    o < VOXEL_CORE && tri_count.get(o as usize).is_some_and(|&c| c > 0)
}

impl Default for Confinement {
    fn default() -> Self {
        Confinement::new(DEFAULT_STIFFNESS)
    }
}

impl Confinement {
    /// A wall of stiffness `stiffness` \[N/m\] with the default reach.
    pub fn new(stiffness: f64) -> Confinement {
        Confinement { stiffness, reach: DEFAULT_REACH }
    }

    /// The allowed voxel nearest to `x` \[m\] within `reach` voxels (its linear index and the
    /// nearest point of its cube), searched ring by ring: `None` if there is none (or `x` is not
    /// finite). `grid` and
    /// `owner` are `HybridModel::grid` and `HybridModel::voxel_owner`; `tri_count` the active
    /// regions per outer triangle.
    pub fn nearest_allowed(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x: &Vec3) -> Option<(usize, Vec3)> {
        if owner.len() != grid.len() || grid.is_empty() || grid.h.is_nan() || grid.h <= 0.0 || !x.iter().all(|c| c.is_finite()) {
            return None;
        }
        const W: usize = 2 * MAX_REACH + 1;
        let reach = self.reach.min(MAX_REACH) as isize;
        let c = grid.cell_clamped(x);
        let h = grid.h;
        // Per axis and offset o: the squared gap from x to the slab of cell c + o (infinite
        // past the grid's edge); a cube's squared distance is the sum over the three axes.
        let mut gap = [[f64::INFINITY; W]; 3];
        for a in 0..3 {
            for o in -reach..=reach {
                let i = c[a] as isize + o;
                if i >= 0 && i < grid.dims[a] as isize {
                    let lo = grid.origin[a] + i as f64 * h;
                    let g = if x[a] < lo {
                        lo - x[a]
                    } else if x[a] > lo + h {
                        x[a] - lo - h
                    } else {
                        0.0
                    };
                    gap[a][(o + MAX_REACH as isize) as usize] = g * g;
                }
            }
        }
        let at = |o: isize| (o + MAX_REACH as isize) as usize;
        let (mut best, mut best_v) = (f64::INFINITY, usize::MAX);
        for ring in 0..=reach {
            // No cube of ring r is nearer than (r - 1) h.
            let bound = ((ring - 1).max(0) as f64) * h;
            if best <= bound * bound {
                break;
            }
            for dk in -ring..=ring {
                let gz = gap[2][at(dk)];
                if gz >= best {
                    continue;
                }
                for dj in -ring..=ring {
                    let gyz = gz + gap[1][at(dj)];
                    if gyz >= best {
                        continue;
                    }
                    // On the ring's shell every cell of the row, inside it only the two ends.
                    let step = if dk.abs() == ring || dj.abs() == ring { 1 } else { 2 * ring };
                    let mut di = -ring;
                    while di <= ring {
                        let g = gyz + gap[0][at(di)];
                        if g < best {
                            let v = grid.index((c[0] as isize + di) as usize, (c[1] as isize + dj) as usize, (c[2] as isize + dk) as usize);
                            if allowed(owner[v], tri_count) {
                                best = g;
                                best_v = v;
                            }
                        }
                        di += step;
                    }
                }
            }
        }
        if best_v == usize::MAX {
            return None;
        }
        let ijk = grid.ijk(best_v);
        let corner = grid.origin + Vec3::new(ijk[0] as f64, ijk[1] as f64, ijk[2] as f64) * h;
        let q = Vec3::new(x.x.clamp(corner.x, corner.x + h), x.y.clamp(corner.y, corner.y + h), x.z.clamp(corner.z, corner.z + h));
        Some((best_v, q))
    }

    /// Distance \[m\] from `x` to the allowed set: 0 inside it, `None` if no allowed voxel is
    /// within reach; with the nearest point of the allowed set.
    fn distance(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x: &Vec3) -> Option<(f64, Vec3)> {
        // The fast path of almost every particle: its own voxel is allowed (one multiply per
        // axis; a point on a cube's face that rounds the other way is found at distance 0 below).
        let inv_h = 1.0 / grid.h;
        let mut v = 0usize;
        let mut stride = 1usize;
        let mut in_grid = true;
        for a in 0..3 {
            let f = ((x[a] - grid.origin[a]) * inv_h).floor();
            if !(f >= 0.0 && f < grid.dims[a] as f64) {
                in_grid = false;
                break;
            }
            v += f as usize * stride;
            stride *= grid.dims[a];
        }
        if in_grid && owner.get(v).is_some_and(|&o| allowed(o, tri_count)) {
            return Some((0.0, *x));
        }
        self.nearest_allowed(grid, owner, tri_count, x).map(|(_, q)| ((x - q).norm(), q))
    }

    /// The wall's force on a particle at `x` \[m\] whose anchor is `anchor` \[m\] (its
    /// rest-embedded position, following the core). The anchor's own distance to the allowed set
    /// is the particle's slack: the potential is `k_c max(0, dist(x) - dist(anchor))^2 / 2`, so
    /// a particle at its anchor feels no wall even where its rest position lies in a voxel
    /// another triangle owns (a few percent of the particles: field lines and projections to the
    /// outer surface do not agree everywhere), and a particle entering the active set at its
    /// anchor starts without a jerk. With no allowed voxel within reach of `x`, the particle is
    /// pulled to its anchor by `k_c |x - anchor|^2 / 2`.
    pub fn push(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x: &Vec3, anchor: &Vec3) -> Push {
        let slack = self.slack(grid, owner, tri_count, anchor);
        self.push_with_slack(grid, owner, tri_count, x, anchor, slack)
    }

    /// A particle's slack \[m\]: its anchor's distance to the allowed set (0 when the anchor is
    /// in it, or has no allowed voxel within reach; NaN for a non-finite anchor). Constant over a
    /// tick's sub-steps when the anchor is (the allowed set changes only at
    /// [`super::activation::Activation::update`]), so a caller may compute it once per tick.
    pub fn slack(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], anchor: &Vec3) -> f64 {
        if !anchor.iter().all(|c| c.is_finite()) {
            return f64::NAN;
        }
        self.distance(grid, owner, tri_count, anchor).map_or(0.0, |(s, _)| s)
    }

    /// [`Confinement::push`] with the slack given (from [`Confinement::slack`]) \[m\].
    pub fn push_with_slack(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x: &Vec3, anchor: &Vec3, slack: f64) -> Push {
        let none = |placement| Push { force: Vec3::zeros(), energy: 0.0, distance: 0.0, placement };
        let finite = |p: &Vec3| p.iter().all(|c| c.is_finite());
        if !finite(x) || !finite(anchor) || !slack.is_finite() {
            return none(Placement::Invalid);
        }
        match self.distance(grid, owner, tri_count, x) {
            Some((d, _)) if d <= 0.0 => none(Placement::Inside),
            Some((d, q)) => {
                let slack = slack.max(0.0);
                if d <= slack {
                    return Push { force: Vec3::zeros(), energy: 0.0, distance: d, placement: Placement::Slack };
                }
                let stretch = d - slack;
                Push {
                    force: -self.stiffness * stretch / d * (x - q),
                    energy: 0.5 * self.stiffness * stretch * stretch,
                    distance: d,
                    placement: Placement::Outside,
                }
            }
            None => {
                let r = x - anchor;
                let d2 = r.norm_squared();
                Push { force: -self.stiffness * r, energy: 0.5 * self.stiffness * d2, distance: d2.sqrt(), placement: Placement::Anchored }
            }
        }
    }

    /// How far \[m\] a particle whose (rest-frame) position is `x0` and whose slack is `slack`
    /// can move from `x0` with the wall surely exerting no force on it (a radius for skipping the
    /// search; a tick computes it once, at its start, and the sub-steps test only the particles
    /// that moved farther). Inside the allowed set: the distance from `x0` to the nearest cube
    /// that is not allowed (or past the grid), looked for among its voxel's 26 neighbours and
    /// bounded beyond them by a cube's width plus `x0`'s distance to its own cube's faces.
    /// Outside it: `min(slack, (reach - 1) h) - dist(x0)`, as the distance to a set grows no
    /// faster than the point moves, and the search finds any allowed cube within `(reach - 1) h`.
    /// Zero when neither holds (or for a non-finite input).
    pub fn free_radius(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x0: &Vec3, slack: f64) -> f64 {
        if owner.len() != grid.len() || grid.is_empty() || !(grid.h > 0.0) || !x0.iter().all(|c| c.is_finite()) || !slack.is_finite() {
            return 0.0;
        }
        let h = grid.h;
        // Past the grid: the search's clamped cell, not worth a bound.
        let Some(cell) = grid.cell_of(x0) else { return 0.0 };
        let c = cell.map(|i| i as isize);
        if !allowed(owner[grid.index_of(cell)], tri_count) {
            return self.outside_free_radius(grid, owner, tri_count, x0, slack);
        }
        // Per axis and offset -1, 0, +1: the squared gap from x0 to that slab.
        let mut gap = [[0.0f64; 3]; 3];
        let mut face = f64::INFINITY;
        for a in 0..3 {
            let lo = grid.origin[a] + c[a] as f64 * h;
            let (below, above) = ((x0[a] - lo).max(0.0), (lo + h - x0[a]).max(0.0));
            gap[a] = [below * below, 0.0, above * above];
            face = face.min(below).min(above);
        }
        let mut best = (face + h) * (face + h);
        for dk in -1..=1isize {
            for dj in -1..=1isize {
                for di in -1..=1isize {
                    let g = gap[0][(di + 1) as usize] + gap[1][(dj + 1) as usize] + gap[2][(dk + 1) as usize];
                    if g >= best || (di, dj, dk) == (0, 0, 0) {
                        continue;
                    }
                    let (i, j, k) = (c[0] + di, c[1] + dj, c[2] + dk);
                    let inside = i >= 0 && j >= 0 && k >= 0 && (i as usize) < grid.dims[0] && (j as usize) < grid.dims[1] && (k as usize) < grid.dims[2];
                    if !inside || !allowed(owner[grid.index(i as usize, j as usize, k as usize)], tri_count) {
                        best = g;
                    }
                }
            }
        }
        best.sqrt()
    }

    /// [`Confinement::free_radius`] outside the allowed set (`x0` in the grid).
    fn outside_free_radius(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], x0: &Vec3, slack: f64) -> f64 {
        let found = (self.reach.min(MAX_REACH) as f64 - 1.0).max(0.0) * grid.h;
        // Staying in the grid (the search starts from the particle's own cell).
        let edge = (0..3)
            .map(|a| (x0[a] - grid.origin[a]).min(grid.origin[a] + grid.dims[a] as f64 * grid.h - x0[a]))
            .fold(f64::INFINITY, f64::min);
        match self.distance(grid, owner, tri_count, x0) {
            Some((d, _)) => (slack.min(found) - d).min(edge).max(0.0),
            None => 0.0,
        }
    }

    /// Write the slacks of the particles `which` (indices into `anchors` and `slacks`; out of
    /// range ones skipped) into `slacks` \[m\], once per tick. Allocation-free.
    pub fn slacks(&self, grid: &VoxelGrid, owner: &[u32], tri_count: &[u32], anchors: &[Vec3], which: &[usize], slacks: &mut [f64]) {
        let n = anchors.len().min(slacks.len());
        for &i in which.iter().filter(|&&i| i < n) {
            slacks[i] = self.slack(grid, owner, tri_count, &anchors[i]);
        }
    }

    /// Add the wall's forces on the particles `which` (indices into `x`, `anchors` and `forces`;
    /// out of range ones skipped) to `forces` \[N\]; returns the sums. With `slacks` (indexed
    /// as `x`, from [`Confinement::slacks`]), the slacks are read instead of searched per call.
    /// Allocation-free.
    #[allow(clippy::too_many_arguments)]
    pub fn apply(
        &self,
        grid: &VoxelGrid,
        owner: &[u32],
        tri_count: &[u32],
        x: &[Vec3],
        anchors: &[Vec3],
        slacks: Option<&[f64]>,
        which: &[usize],
        forces: &mut [Vec3],
    ) -> ConfinementSum {
        let mut sum = ConfinementSum::default();
        let n = x.len().min(anchors.len()).min(forces.len()).min(slacks.map_or(usize::MAX, |s| s.len()));
        for &i in which {
            if i >= n {
                continue;
            }
            let p = match slacks {
                Some(s) => self.push_with_slack(grid, owner, tri_count, &x[i], &anchors[i], s[i]),
                None => self.push(grid, owner, tri_count, &x[i], &anchors[i]),
            };
            match p.placement {
                Placement::Inside | Placement::Slack => continue,
                Placement::Invalid => {
                    sum.invalid += 1;
                    continue;
                }
                Placement::Anchored => sum.anchored += 1,
                Placement::Outside => {}
            }
            forces[i] += p.force;
            sum.pushed += 1;
            sum.energy += p.energy;
            sum.max_distance = sum.max_distance.max(p.distance);
        }
        sum
    }
}
