//! The outer surface of the wall (where the tool touches): its vertices carry the activation
//! regions and the skin; its section of the model file. Its adjacency is derived, not stored.

use super::file::{finite, in_range, Reader, Res, Writer};
use super::model::HybridModel;
use super::transmural::WallPart;
use super::wall::Wall;
use crate::mesh::adjacency::SurfaceAdjacency;
use crate::spatial::TriangleGrid;

/// The outer part of `wall`, with its adjacency.
pub(super) fn build(m: &mut HybridModel, wall: &Wall) {
    let part = wall.part(WallPart::Outer);
    m.outer_adjacency = SurfaceAdjacency::new(part.points.len(), &part.tris);
    m.outer_points = part.points;
    m.outer_tris = part.tris;
}

/// A nearest-triangle grid of the outer surface, cells about its mean edge (at least
/// `min_cell` \[m\]).
pub(super) fn grid(m: &HybridModel, min_cell: f64) -> TriangleGrid {
    let (p, tris) = (&m.outer_points, &m.outer_tris);
    let area: f64 = tris.iter().map(|t| (p[t[1]] - p[t[0]]).cross(&(p[t[2]] - p[t[0]])).norm() * 0.5).sum();
    let edge = (area / tris.len() as f64 * 2.3).sqrt();
    TriangleGrid::new(p, tris, edge.max(min_cell))
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.vec3s(&m.outer_points);
    w.idx(&m.outer_tris);
}

/// The section; the adjacency is filled in by [`derive`] once the model is checked.
// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.outer_points = r.vec3s("outer points")?;
    m.outer_tris = r.idx::<3>("outer triangles")?;
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    in_range("outer triangles", m.outer_tris.iter().flatten().copied(), m.outer_points.len())?;
    finite("outer points", &m.outer_points)
}

/// The adjacency of a loaded (and checked) model.
pub(super) fn derive(m: &mut HybridModel) {
    m.outer_adjacency = SurfaceAdjacency::new(m.outer_points.len(), &m.outer_tris);
}
