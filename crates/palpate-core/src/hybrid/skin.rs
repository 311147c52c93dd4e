//! The skin (paper §4): each outer vertex tied to the core face its projection hits, by
//! barycentric coordinates on that face and the rest offset from the anchor point to the
//! vertex; the skin's section of the model file.

use super::file::{finite, in_range, Reader, Res, Writer};
use super::model::HybridModel;
use super::shell::{CoreHit, Projector};
use crate::math::Vec3;

/// The skin fields of `m` (its core and outer surface built); returns how many projections
/// fell back to the nearest point.
pub(super) fn build(m: &mut HybridModel, project: &Projector) -> usize {
    let mut fallbacks = 0;
    let hits: Vec<CoreHit> = m.outer_points.iter().map(|p| project.core_of(m, p, &mut fallbacks)).collect();
    m.skin_face = hits.iter().map(|h| h.face).collect();
    m.skin_bary = hits.iter().map(|h| h.bary).collect();
    m.skin_offset = m.outer_points.iter().zip(&hits).map(|(p, h)| p - h.point).collect();
    fallbacks
}

impl HybridModel {
    /// Rest anchor point of outer vertex `v` on its core face \[m\].
    pub fn skin_anchor(&self, v: usize) -> Vec3 {
        let f = self.core_faces[self.skin_face[v] as usize];
        let b = self.skin_bary[v];
        b[0] * self.core_points[f[0]] + b[1] * self.core_points[f[1]] + b[2] * self.core_points[f[2]]
    }
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.u32s(&m.skin_face);
    w.rows(&m.skin_bary, |w, x| w.f64(x));
    w.vec3s(&m.skin_offset);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.skin_face = r.u32s("skin faces")?;
    m.skin_bary = r.rows(8, "skin barycentric coordinates", |r| r.f64("skin barycentric coordinates"))?;
    m.skin_offset = r.vec3s("skin offsets")?;
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    let no = m.outer_points.len();
    if m.skin_face.len() != no || m.skin_bary.len() != no || m.skin_offset.len() != no {
        return Err("per-outer-vertex arrays of different lengths".into());
    }
    in_range("skin faces", m.skin_face.iter().map(|&x| x as usize), m.core_faces.len())?;
    finite("skin offsets", &m.skin_offset)
}
