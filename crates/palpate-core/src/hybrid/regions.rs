//! The activation regions (paper §4), one per outer vertex p_s: nv(p_s), the outer triangles
//! within a number of rings of p_s, grown until RV(p_s) (the particles under them) is large
//! enough; C(p_s), the projections of nv's boundary onto the core; and the box B(p_s) in the
//! shared voxels. A region stores its ring count and box; the rest is regrown on demand. The
//! regions' section of the model file.

use super::file::{Reader, Res, Writer};
use super::model::HybridModel;
use super::options::MAX_RINGS;
use crate::math::Vec3;
use crate::mesh::adjacency::Marks;

/// nv(p_s) grows by rings of triangles until RV(p_s) holds `min_particles` (at most
/// [`MAX_RINGS`] rings, further only while empty); B(p_s) is the voxel box of RV(p_s) (of p_s
/// if RV is empty) with one voxel of margin, clamped to the grid. Sets the region fields of `m`
/// (its outer surface, voxels and shell built).
pub(super) fn build(m: &mut HybridModel) {
    let (ptr, grid, min_particles) = (&m.tri_particle_ptr, &m.grid, m.options.min_region_particles);
    let count = |t: u32| (ptr[t as usize + 1] - ptr[t as usize]) as usize;
    let mut in_patch = vec![false; m.outer_tris.len()];
    let mut rings = Vec::with_capacity(m.outer_points.len());
    let mut boxes = Vec::with_capacity(m.outer_points.len());
    for s in 0..m.outer_points.len() {
        let mut n = 0;
        let patch = m.outer_adjacency.patch(&m.outer_tris, s, None, Marks::Flags(&mut in_patch), |r, added| {
            n += added.iter().map(|&t| count(t)).sum::<usize>();
            !(n >= min_particles || (r >= MAX_RINGS && n > 0) || r >= 2 * MAX_RINGS)
        });
        rings.push(patch.rings.min(255) as u8);
        let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
        for &t in &patch.triangles {
            for q in ptr[t as usize] as usize..ptr[t as usize + 1] as usize {
                if let Some(c) = grid.cell_of(&m.particles[q]) {
                    for a in 0..3 {
                        lo[a] = lo[a].min(c[a] as u32);
                        hi[a] = hi[a].max(c[a] as u32);
                    }
                }
            }
        }
        if lo[0] == u32::MAX {
            let c = grid.cell_of(&m.outer_points[s]).unwrap_or([0, 0, 0]);
            lo = [c[0] as u32, c[1] as u32, c[2] as u32];
            hi = lo;
        }
        // One voxel of margin, clamped to the grid.
        let mut b = [0u32; 6];
        for a in 0..3 {
            b[a] = lo[a].saturating_sub(1);
            b[a + 3] = (hi[a] + 2).min(grid.dims[a] as u32);
        }
        boxes.push(b);
    }
    m.region_rings = rings;
    m.region_box = boxes;
}

impl HybridModel {
    /// nv(p_s) of region `s`: its outer triangles, sorted (grown from the stored ring count in
    /// microseconds).
    pub fn region_triangles(&self, s: usize) -> Vec<u32> {
        self.outer_adjacency
            .patch(&self.outer_tris, s, Some(self.region_rings[s] as usize), Marks::Sorted(Vec::new()), |_, _| false)
            .triangles
    }

    /// RV(p_s): the particles of region `s`, as ranges into [`HybridModel::particles`] (one per
    /// triangle of nv(p_s): particles are sorted by the outer triangle above them).
    pub fn region_particle_ranges(&self, s: usize) -> Vec<std::ops::Range<usize>> {
        self.region_triangles(s)
            .iter()
            .map(|&t| self.tri_particle_ptr[t as usize] as usize..self.tri_particle_ptr[t as usize + 1] as usize)
            .collect()
    }

    /// Number of particles in RV(p_s).
    pub fn region_len(&self, s: usize) -> usize {
        self.region_particle_ranges(s).iter().map(|r| r.len()).sum()
    }

    /// Core faces under RV(p_s) (the faces below its particles; the skin face of `s` if it has
    /// none), sorted.
    pub fn region_core_faces(&self, s: usize) -> Vec<u32> {
        let mut f: Vec<u32> = self.region_particle_ranges(s).into_iter().flatten().map(|q| self.particle_core_face[q]).collect();
        if f.is_empty() {
            f.push(self.skin_face[s]);
        }
        f.sort_unstable();
        f.dedup();
        f
    }

    /// The boundary vertices of nv(p_s) (outer vertex indices), in loop order.
    pub fn region_rim(&self, s: usize) -> Vec<u32> {
        self.outer_adjacency.rim(&self.outer_tris, &self.region_triangles(s))
    }

    /// C(p_s): the projections on the core of nv(p_s)'s boundary vertices \[m\].
    pub fn region_curve(&self, s: usize) -> Vec<Vec3> {
        self.region_rim(s).iter().map(|&v| self.skin_anchor(v as usize)).collect()
    }
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.bytes(&m.region_rings);
    w.rows(&m.region_box, |w, x| w.u32(x));
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.region_rings = r.bytes("region rings")?;
    m.region_box = r.rows(4, "region boxes", |r| r.u32("region boxes"))?;
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    if let Some(s) = m.region_rings.iter().position(|&r| r == 0) {
        return Err(format!("region {s}: zero rings"));
    }
    if m.region_rings.len() != m.outer_points.len() || m.region_box.len() != m.outer_points.len() {
        return Err("per-outer-vertex arrays of different lengths".into());
    }
    let dims = m.grid.dims;
    for (s, b) in m.region_box.iter().enumerate() {
        for a in 0..3 {
            if b[a] >= b[a + 3] || b[a + 3] as usize > dims[a] {
                return Err(format!("region {s}: voxel box {b:?} outside the grid {dims:?}"));
            }
        }
    }
    Ok(())
}
