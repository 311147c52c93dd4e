//! The shared voxels and B(p_s) (paper §4, Fig. 5): one voxel grid records, per wall voxel, the
//! outer triangle its field line reaches; the box of each region, its labels and its gradient
//! field are computed from it on demand. The voxels' section of the model file.

use super::file::{Reader, Res, Writer};
use super::model::HybridModel;
use super::shell::Projector;
use super::transmural::{Transmural, VoxelGrid};
use crate::math::Vec3;
use crate::spatial::{Grid3, TetGrid};

/// `voxel_owner` of a voxel outside the wall.
pub const VOXEL_OUTSIDE: u32 = u32::MAX;
/// `voxel_owner` of a wall voxel inside the FEM core.
pub const VOXEL_CORE: u32 = u32::MAX - 1;

/// The outer triangle above each wall voxel. Wall voxels in order of decreasing phi: a voxel
/// takes the owner of the wall voxel one step along the field from its centre when that one has
/// an owner already (one field line each), and marches to the outer surface itself otherwise
/// (the outermost layer, and where field lines leave through a base). Sets the voxel fields of
/// `m` (its core and outer surface built); returns the marches that fell back to the nearest
/// point.
pub(super) fn owners(m: &mut HybridModel, field: &Transmural, core_grid: &TetGrid, project: &Projector) -> usize {
    let grid = field.grid;
    let mut owner = vec![VOXEL_OUTSIDE; grid.len()];
    let mut order: Vec<usize> = (0..grid.len()).filter(|&v| field.wall[v]).collect();
    order.sort_by(|&a, &b| field.phi[b].total_cmp(&field.phi[a]));
    let mut fallbacks = 0;
    for &v in &order {
        let c = grid.centre(v);
        if core_grid.locate(&m.core_points, &c).is_some() {
            owner[v] = VOXEL_CORE;
            continue;
        }
        let ahead = c + grid.h * field.dir_at(&c, m.options.projection);
        let inherited = grid.cell_of(&ahead).map(|a| owner[grid.index_of(a)]).filter(|&w| w < VOXEL_CORE);
        owner[v] = match inherited {
            Some(w) => w,
            None => project.outer_of(m, &c, &mut fallbacks),
        };
    }
    m.grid = grid;
    m.voxel_owner = owner;
    fallbacks
}

impl HybridModel {
    /// B(p_s) with its labels and gradient field, computed from the shared voxels (see
    /// [`RegionField`]).
    pub fn region_field(&self, s: usize) -> RegionField {
        let b = self.region_box[s];
        let origin = self.grid.origin + Vec3::new(b[0] as f64, b[1] as f64, b[2] as f64) * self.grid.h;
        let boxed = Grid3 { origin, h: self.grid.h, dims: [(b[3] - b[0]) as usize, (b[4] - b[1]) as usize, (b[5] - b[2]) as usize] };
        let n = boxed.len();
        let tris = self.region_triangles(s);
        let mut label = vec![VoxelLabel::Outside; n];
        for (v, l) in label.iter_mut().enumerate() {
            let c = boxed.ijk(v);
            let o = self.voxel_owner[self.grid.index(b[0] as usize + c[0], b[1] as usize + c[1], b[2] as usize + c[2])];
            if o < VOXEL_CORE && tris.binary_search(&o).is_ok() {
                *l = VoxelLabel::Inside;
            }
        }
        // Boundary: inside voxels with a face-neighbour outside the region (or the box).
        let snapshot = label.clone();
        for (v, l) in label.iter_mut().enumerate() {
            if snapshot[v] == VoxelLabel::Inside && boxed.face_neighbours(v).iter().any(|w| w.is_none_or(|w| snapshot[w] == VoxelLabel::Outside)) {
                *l = VoxelLabel::Boundary;
            }
        }
        // Gradient: the unit vector to the nearest interior voxel (or, if the region has none,
        // the nearest boundary voxel), by exact Euclidean search over the box (a few hundred
        // voxels).
        let target = if label.contains(&VoxelLabel::Inside) { VoxelLabel::Inside } else { VoxelLabel::Boundary };
        let ijk = |v: usize| boxed.ijk(v).map(|x| x as f64);
        let targets: Vec<[f64; 3]> = (0..n).filter(|&v| label[v] == target).map(ijk).collect();
        let gradient = (0..n)
            .map(|v| {
                if label[v] == target || targets.is_empty() {
                    return [0.0f32; 3];
                }
                let p = ijk(v);
                let mut best = (f64::INFINITY, [0.0; 3]);
                for t in &targets {
                    let d2 = (t[0] - p[0]).powi(2) + (t[1] - p[1]).powi(2) + (t[2] - p[2]).powi(2);
                    if d2 < best.0 {
                        best = (d2, *t);
                    }
                }
                let d = Vec3::new(best.1[0] - p[0], best.1[1] - p[1], best.1[2] - p[2]).normalize();
                [d.x as f32, d.y as f32, d.z as f32]
            })
            .collect();
        RegionField { origin, h: self.grid.h, dims: boxed.dims, label, gradient }
    }
}

/// Label of a voxel of B(p_s).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VoxelLabel {
    /// Not in RV(p_s).
    Outside,
    /// In RV(p_s), away from its boundary.
    Inside,
    /// In RV(p_s), with a face-neighbour outside it (or the box edge): the confinement layer.
    Boundary,
}

/// B(p_s): a voxel box (x fastest) with labels and the unit gradient field (Fig. 5): at
/// boundary and outside voxels it points to the nearest interior voxel, zero inside.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionField {
    /// Corner of the box \[m\].
    pub origin: Vec3,
    /// Voxel edge \[m\].
    pub h: f64,
    pub dims: [usize; 3],
    pub label: Vec<VoxelLabel>,
    pub gradient: Vec<[f32; 3]>,
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.vec3(&m.grid.origin);
    w.f64(m.grid.h);
    m.grid.dims.iter().for_each(|&d| w.u64(d as u64));
    w.u32s(&m.voxel_owner);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    let origin = r.vec3("voxel grid")?;
    let h = r.f64("voxel grid")?;
    let dims = [r.u64("voxel grid")? as usize, r.u64("voxel grid")? as usize, r.u64("voxel grid")? as usize];
    m.grid = VoxelGrid { origin, h, dims };
    m.voxel_owner = r.u32s("voxel owners")?;
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    let g = &m.grid;
    // Each defect named (issue 35 item 6: a negative spacing was reported as "inconsistent").
    if !(g.h > 0.0 && g.h.is_finite()) {
        return Err(format!("voxel grid spacing {} m must be positive and finite", g.h));
    }
    if let Some(d) = g.dims.iter().find(|&&d| d == 0 || d > 1 << 20) {
        return Err(format!("voxel grid of {:?} voxels: {d} voxels along an axis (1 to {} allowed)", g.dims, 1 << 20));
    }
    if m.voxel_owner.len() != g.dims.iter().product::<usize>() {
        return Err(format!("voxel grid of {:?} voxels has {} voxel owners", g.dims, m.voxel_owner.len()));
    }
    Ok(())
}
