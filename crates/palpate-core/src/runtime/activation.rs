//! Local activation (paper §6): the active particles are the union of RV(p_s) over the regions
//! the tool touches, with hysteresis.
//!
//! A region `s` (one per outer vertex) is nv(p_s), the outer triangles within
//! `HybridModel::region_rings[s]` rings of `s`; RV(p_s) is the particles under them, and the
//! particles of outer triangle `t` are `tri_particle_ptr[t]..tri_particle_ptr[t+1]` (particles
//! are sorted by the triangle above them). [`Activation`] precomputes each region's triangles
//! once as a CSR table ([`Buckets`]: one `u32` per (region, triangle) pair: 263 KB on the
//! synthetic ventricle of the tests, 2,305 regions of 28 triangles on average; on the Rodero
//! model, whose fine outer mesh makes regions of many rings, the model-file sizes in
//! ARCHITECTURE.md suggest up to ~25 MB, against ~100 MB for stored voxel boxes; should that
//! matter, a region can be regrown from its ring count when touched, allocation-free with
//! per-triangle flags, at a few microseconds per new region) and keeps, per outer triangle, how many
//! active regions cover it: a triangle is active while its count is positive, and its particles
//! with it. The union thus never holds a particle twice, and the active list stays sorted.
//!
//! Hysteresis: a region touched at tick `T` stays active through tick `T + linger` and leaves at
//! tick `T + linger + 1` unless touched again, so a slide does not toggle the particles at the
//! edge of the patch every tick.
//!
//! Per tick (allocation-free: every list has its capacity from [`Activation::new`]):
//! `touch(s)` for each outer vertex under the tool ([`Activation::touch_sphere`] finds them),
//! then `update(tick)`, which returns the active, entered and left particles.

use crate::hybrid::HybridModel;
use crate::math::Vec3;
use crate::mesh::adjacency::Marks;
use crate::spatial::Buckets;
use std::sync::Arc;

/// `last_touched` of a region never touched.
const NEVER: u64 = u64::MAX;

/// The particles of this tick ([`Activation::update`]), each list sorted and without repeats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ActiveSets<'a> {
    /// All active particles (indices into `HybridModel::particles`).
    pub active: &'a [usize],
    /// Particles active now and not at the previous update.
    pub entered: &'a [usize],
    /// Particles active at the previous update and not now.
    pub left: &'a [usize],
}

/// The active set: the union of the touched regions' particles, with hysteresis. Built once from
/// a [`HybridModel`]; `touch`, `touch_sphere` and `update` allocate nothing, and neither does
/// `clone_from` onto an activation of the same model (the haptic loop's checkpoints): the
/// region tables, fixed at build, are shared between clones.
#[derive(Debug)]
pub struct Activation {
    /// Triangles of each region (sorted): `region_tris.get(s)`. Immutable, shared by clones (on
    /// the Rodero model ~8 MB: copying it made a checkpoint of the state cost 2.5 ms).
    region_tris: Arc<Buckets>,
    /// Particles of outer triangle `t`: `tri_particle_ptr[t]..tri_particle_ptr[t+1]`. Immutable,
    /// shared by clones.
    tri_particle_ptr: Arc<[u32]>,
    /// Active regions covering each outer triangle.
    tri_count: Vec<u32>,
    /// The triangles with a positive count (unordered): the skin's update visits each once
    /// (through the regions, a triangle shared by k active regions was visited k times).
    triangles: Vec<u32>,
    /// Per region: the tick of its last contact ([`NEVER`] if none).
    last_touched: Vec<u64>,
    /// Per region: in `regions` (active) or in `pending`.
    is_active: Vec<bool>,
    is_pending: Vec<bool>,
    /// Regions touched since the last update.
    pending: Vec<u32>,
    /// Active regions (unordered).
    regions: Vec<u32>,
    /// Ticks a region stays active after its last contact.
    linger: u64,
    /// Triangles that turned on / off in this update (scratch).
    tri_on: Vec<u32>,
    tri_off: Vec<u32>,
    active: Vec<usize>,
    scratch: Vec<usize>,
    entered: Vec<usize>,
    left: Vec<usize>,
    /// Mean outer edge length \[m\] (a margin for [`Activation::touch_sphere`]).
    mean_edge: f64,
}

impl Clone for Activation {
    fn clone(&self) -> Self {
        let mut a = Activation {
            region_tris: self.region_tris.clone(),
            tri_particle_ptr: self.tri_particle_ptr.clone(),
            tri_count: Vec::new(),
            triangles: Vec::new(),
            last_touched: Vec::new(),
            is_active: Vec::new(),
            is_pending: Vec::new(),
            pending: Vec::new(),
            regions: Vec::new(),
            linger: self.linger,
            tri_on: Vec::new(),
            tri_off: Vec::new(),
            active: Vec::new(),
            scratch: Vec::new(),
            entered: Vec::new(),
            left: Vec::new(),
            mean_edge: self.mean_edge,
        };
        a.clone_from(self);
        a
    }

    /// Field by field, into the allocations `self` has (none once they are large enough), and
    /// with the capacities the updates rely on to allocate nothing.
    fn clone_from(&mut self, s: &Self) {
        // Exhaustive: a new field is a compile error here until it is copied.
        let Activation {
            region_tris,
            tri_particle_ptr,
            tri_count,
            triangles,
            last_touched,
            is_active,
            is_pending,
            pending,
            regions,
            linger,
            tri_on,
            tri_off,
            active,
            scratch,
            entered,
            left,
            mean_edge,
        } = self;
        if !Arc::ptr_eq(region_tris, &s.region_tris) {
            *region_tris = s.region_tris.clone();
        }
        if !Arc::ptr_eq(tri_particle_ptr, &s.tri_particle_ptr) {
            *tri_particle_ptr = s.tri_particle_ptr.clone();
        }
        let (n_regions, n_tris, n_particles) = (s.last_touched.len(), s.tri_count.len(), s.active.capacity().max(s.scratch.capacity()));
        copy_into(tri_count, &s.tri_count, n_tris);
        copy_into(triangles, &s.triangles, n_tris);
        copy_into(last_touched, &s.last_touched, n_regions);
        copy_into(is_active, &s.is_active, n_regions);
        copy_into(is_pending, &s.is_pending, n_regions);
        copy_into(pending, &s.pending, n_regions);
        copy_into(regions, &s.regions, n_regions);
        *linger = s.linger;
        copy_into(tri_on, &s.tri_on, n_tris);
        copy_into(tri_off, &s.tri_off, n_tris);
        copy_into(active, &s.active, n_particles);
        copy_into(scratch, &s.scratch, n_particles);
        copy_into(entered, &s.entered, n_particles);
        copy_into(left, &s.left, n_particles);
        *mean_edge = s.mean_edge;
    }
}

/// `dst = src`, keeping at least `capacity` (allocating only if `dst` has less).
fn copy_into<T: Copy>(dst: &mut Vec<T>, src: &[T], capacity: usize) {
    dst.clear();
    dst.reserve(capacity.max(src.len()));
    dst.extend_from_slice(src);
}

impl Activation {
    /// The activation of `model`'s regions, a region lingering `linger_ticks` ticks after its
    /// last contact. Builds the region-triangle table (the one allocating step). A model whose
    /// region or triangle tables are inconsistent (as a loaded file's `check` refuses) gives
    /// regions without triangles rather than a panic.
    pub fn new(model: &HybridModel, linger_ticks: u64) -> Activation {
        let n_regions = model.region_rings.len().min(model.outer_points.len());
        let n_tris = model.outer_tris.len();
        let tris_ok = model.outer_adjacency.across.len() == n_tris
            && model.outer_adjacency.vertex_tris.ptr.len() == model.outer_points.len() + 1
            && model.outer_tris.iter().flatten().all(|&v| v < model.outer_points.len());
        let mut flags = vec![false; n_tris];
        let mut ptr = Vec::with_capacity(n_regions + 1);
        let mut items: Vec<u32> = Vec::new();
        ptr.push(0u32);
        for s in 0..n_regions {
            if tris_ok {
                let rings = (model.region_rings[s] as usize).max(1);
                let patch = model.outer_adjacency.patch(&model.outer_tris, s, Some(rings), Marks::Flags(&mut flags), |_, _| false);
                items.extend_from_slice(&patch.triangles);
            }
            ptr.push(items.len() as u32);
        }
        let region_tris = Buckets { ptr, items };
        // Per-triangle particle ranges, clamped so a damaged table cannot index past the particles.
        let n_particles = model.particles.len() as u32;
        let mut tri_particle_ptr: Vec<u32> = if model.tri_particle_ptr.len() == n_tris + 1 {
            model.tri_particle_ptr.clone()
        } else {
            vec![0; n_tris + 1]
        };
        let mut lo = 0;
        for p in tri_particle_ptr.iter_mut() {
            *p = (*p).clamp(lo, n_particles);
            lo = *p;
        }
        let np = model.particles.len();
        let mut edge = (0.0, 0usize);
        for t in &model.outer_tris {
            for k in 0..3 {
                if let (Some(a), Some(b)) = (model.outer_points.get(t[k]), model.outer_points.get(t[(k + 1) % 3])) {
                    edge.0 += (a - b).norm();
                    edge.1 += 1;
                }
            }
        }
        Activation {
            region_tris: Arc::new(region_tris),
            tri_particle_ptr: tri_particle_ptr.into(),
            tri_count: vec![0; n_tris],
            triangles: Vec::with_capacity(n_tris),
            last_touched: vec![NEVER; n_regions],
            is_active: vec![false; n_regions],
            is_pending: vec![false; n_regions],
            pending: Vec::with_capacity(n_regions),
            regions: Vec::with_capacity(n_regions),
            linger: linger_ticks,
            tri_on: Vec::with_capacity(n_tris),
            tri_off: Vec::with_capacity(n_tris),
            active: Vec::with_capacity(np),
            scratch: Vec::with_capacity(np),
            entered: Vec::with_capacity(np),
            left: Vec::with_capacity(np),
            mean_edge: if edge.1 > 0 { edge.0 / edge.1 as f64 } else { 0.0 },
        }
    }

    /// Number of regions (outer vertices).
    pub fn n_regions(&self) -> usize {
        self.last_touched.len()
    }

    /// Number of outer triangles.
    pub fn n_triangles(&self) -> usize {
        self.tri_count.len()
    }

    /// The triangles of region `s`, sorted (empty for `s` out of range).
    pub fn region_triangles(&self, s: usize) -> &[u32] {
        if s < self.n_regions() {
            self.region_tris.get(s)
        } else {
            &[]
        }
    }

    /// The region-triangle table's size \[bytes\].
    pub fn table_bytes(&self) -> usize {
        4 * (self.region_tris.ptr.len() + self.region_tris.items.len())
    }

    /// Ticks a region stays active after its last contact.
    pub fn linger(&self) -> u64 {
        self.linger
    }

    /// Regions now linger `ticks` ticks after their last contact (the runtime sets it each tick
    /// from [`crate::runtime::SimOptions::linger`] and the tick's length).
    pub fn set_linger(&mut self, ticks: u64) {
        self.linger = ticks;
    }

    /// Mean edge length of the outer surface \[m\]: a margin for [`Activation::touch_sphere`] that
    /// catches the vertices of the triangles a sphere presses between vertices.
    pub fn mean_edge(&self) -> f64 {
        self.mean_edge
    }

    /// Mark region `s` as touched this tick (takes effect at the next [`Activation::update`]);
    /// false for `s` out of range.
    pub fn touch(&mut self, s: usize) -> bool {
        if s >= self.n_regions() {
            return false;
        }
        if !self.is_pending[s] {
            self.is_pending[s] = true;
            self.pending.push(s as u32);
        }
        true
    }

    /// Touch every region whose outer vertex lies within `radius + margin` \[m\] of `centre` \[m\];
    /// `vertices` are the outer vertices' current positions \[m\] (the skin), one per region.
    /// Returns the number touched. A sweep of every vertex (the tick looks only at those that can
    /// be within reach: [`Activation::touch_sphere_among`]).
    pub fn touch_sphere(&mut self, centre: &Vec3, radius: f64, margin: f64, vertices: &[Vec3]) -> usize {
        self.touch_sphere_among(centre, radius, margin, vertices, 0..vertices.len())
    }

    /// [`Activation::touch_sphere`] looking only at the vertices `among` (indices into
    /// `vertices`, in the order their regions are to be touched; out of range ones skipped):
    /// the tick passes the skin vertices that can be within reach.
    pub fn touch_sphere_among(&mut self, centre: &Vec3, radius: f64, margin: f64, vertices: &[Vec3], among: impl Iterator<Item = usize>) -> usize {
        let reach = radius + margin;
        if !(reach >= 0.0 && reach.is_finite()) {
            return 0;
        }
        let r2 = reach * reach;
        let mut n = 0;
        let n_regions = self.n_regions().min(vertices.len());
        for s in among.filter(|&s| s < n_regions) {
            if (vertices[s] - centre).norm_squared() <= r2 && self.touch(s) {
                n += 1;
            }
        }
        n
    }

    /// Advance to tick `tick`: the touched regions become (or stay) active with `tick` as their
    /// last contact, and the regions last touched more than `linger` ticks ago leave. Returns the
    /// active particles and those that entered and left since the previous update.
    pub fn update(&mut self, tick: u64) -> ActiveSets<'_> {
        self.tri_on.clear();
        self.tri_off.clear();
        // Arrivals first, so that a triangle shared by an arriving and a leaving region stays on.
        for k in 0..self.pending.len() {
            let s = self.pending[k] as usize;
            self.is_pending[s] = false;
            self.last_touched[s] = tick;
            if !self.is_active[s] {
                self.is_active[s] = true;
                self.regions.push(s as u32);
                for &t in self.region_tris.get(s) {
                    let c = &mut self.tri_count[t as usize];
                    *c += 1;
                    if *c == 1 {
                        self.tri_on.push(t);
                    }
                }
            }
        }
        self.pending.clear();
        let mut k = 0;
        while k < self.regions.len() {
            let s = self.regions[k] as usize;
            if tick.saturating_sub(self.last_touched[s]) > self.linger {
                self.is_active[s] = false;
                self.regions.swap_remove(k);
                for &t in self.region_tris.get(s) {
                    let c = &mut self.tri_count[t as usize];
                    *c -= 1;
                    if *c == 0 {
                        self.tri_off.push(t);
                    }
                }
            } else {
                k += 1;
            }
        }
        // A triangle turned on then off in one update cannot happen (arrivals are not expired),
        // but one turned off may have been on before: tri_on and tri_off are disjoint.
        if !self.tri_off.is_empty() {
            let count = &self.tri_count;
            self.triangles.retain(|&t| count[t as usize] > 0);
        }
        self.triangles.extend_from_slice(&self.tri_on);
        self.tri_on.sort_unstable();
        self.tri_off.sort_unstable();
        self.entered.clear();
        self.left.clear();
        for &t in &self.tri_on {
            let (a, b) = (self.tri_particle_ptr[t as usize] as usize, self.tri_particle_ptr[t as usize + 1] as usize);
            self.entered.extend(a..b);
        }
        for &t in &self.tri_off {
            let (a, b) = (self.tri_particle_ptr[t as usize] as usize, self.tri_particle_ptr[t as usize + 1] as usize);
            self.left.extend(a..b);
        }
        if !self.entered.is_empty() || !self.left.is_empty() {
            // active <- (active \ left) merged with entered, all sorted.
            self.scratch.clear();
            let (mut i, mut l, mut e) = (0, 0, 0);
            while i < self.active.len() || e < self.entered.len() {
                let a = self.active.get(i).copied().unwrap_or(usize::MAX);
                let n = self.entered.get(e).copied().unwrap_or(usize::MAX);
                if a <= n {
                    while l < self.left.len() && self.left[l] < a {
                        l += 1;
                    }
                    if !(l < self.left.len() && self.left[l] == a) {
                        self.scratch.push(a);
                    }
                    i += 1;
                    if a == n {
                        e += 1;
                    }
                } else {
                    self.scratch.push(n);
                    e += 1;
                }
            }
            std::mem::swap(&mut self.active, &mut self.scratch);
        }
        self.sets()
    }

    /// The lists of the last [`Activation::update`].
    pub fn sets(&self) -> ActiveSets<'_> {
        ActiveSets { active: &self.active, entered: &self.entered, left: &self.left }
    }

    /// The active particles (sorted).
    pub fn active(&self) -> &[usize] {
        &self.active
    }

    /// The active regions (unordered).
    pub fn active_regions(&self) -> &[u32] {
        &self.regions
    }

    /// Is region `s` active?
    pub fn is_region_active(&self, s: usize) -> bool {
        self.is_active.get(s).copied().unwrap_or(false)
    }

    /// Is outer triangle `t` active (covered by an active region)?
    #[inline]
    pub fn is_triangle_active(&self, t: u32) -> bool {
        self.tri_count.get(t as usize).is_some_and(|&c| c > 0)
    }

    /// Per outer triangle: the number of active regions covering it (> 0: active). The slice
    /// [`super::confinement`] reads.
    pub fn triangle_counts(&self) -> &[u32] {
        &self.tri_count
    }

    /// The outer triangles under an active region, each once, in no particular order.
    pub fn active_triangles(&self) -> &[u32] {
        &self.triangles
    }

    /// Per region: the tick of its last contact (`u64::MAX`: never touched).
    pub fn last_touched(&self) -> &[u64] {
        &self.last_touched
    }

    /// Bring the activation to the one whose [`Activation::last_touched`] and
    /// [`Activation::active_regions`] (in that order: the order decides nothing but is kept, so
    /// that the next updates repeat the saved activation's bit for bit) these are, as after an
    /// update: the triangle counts and the active particles follow from them, nothing is pending
    /// and nothing entered or left. Errors (the activation unchanged): a wrong length, an active
    /// region out of range, repeated or never touched.
    pub fn restore(&mut self, last_touched: &[u64], regions: &[u32]) -> Result<(), String> {
        let n = self.n_regions();
        if last_touched.len() != n {
            return Err(format!("last contacts of {} regions, the model has {n}", last_touched.len()));
        }
        let mut seen = vec![false; n];
        for &s in regions {
            let s = s as usize;
            if s >= n || seen[s] || last_touched[s] == NEVER {
                return Err(format!("active region {s} is out of range ({n} regions), repeated or never touched"));
            }
            seen[s] = true;
        }
        self.clear();
        self.last_touched.copy_from_slice(last_touched);
        self.is_active = seen;
        self.regions.extend_from_slice(regions);
        for &s in regions {
            for &t in self.region_tris.get(s as usize) {
                self.tri_count[t as usize] += 1;
            }
        }
        // Particles are sorted by the triangle above them: in triangle order, the union comes
        // out sorted, as update's merge keeps it.
        for (t, &c) in self.tri_count.iter().enumerate() {
            if c > 0 {
                self.triangles.push(t as u32);
                self.active.extend(self.tri_particle_ptr[t] as usize..self.tri_particle_ptr[t + 1] as usize);
            }
        }
        Ok(())
    }

    /// Deactivate everything at once (e.g. on a reset); the next update reports no change.
    pub fn clear(&mut self) {
        for &s in &self.regions {
            self.is_active[s as usize] = false;
        }
        for &s in &self.pending {
            self.is_pending[s as usize] = false;
        }
        self.regions.clear();
        self.pending.clear();
        self.tri_count.iter_mut().for_each(|c| *c = 0);
        self.triangles.clear();
        self.last_touched.iter_mut().for_each(|t| *t = NEVER);
        self.active.clear();
        self.entered.clear();
        self.left.clear();
    }
}
