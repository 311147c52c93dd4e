//! Walls that ship with palpate: the paper's two concentric ellipsoids and the synthetic
//! truncated ventricle of the benchmark protocol.

use super::transmural::WallPart;
use super::wall::Wall;
use crate::error::HybridError;
use crate::mesh::generate::{try_truncated_ellipsoid_wall, TruncatedEllipsoidWall};
use crate::mesh::{ellipsoid_surface, TriSurface};

/// The paper's "Ellipsoids Model" wall: concentric ellipsoids of semi-axes `inner` and `outer`
/// \[m\], each an octahedron refined `subdivisions` times (`8 * 4^s` triangles).
pub fn ellipsoids(inner: [f64; 3], outer: [f64; 3], subdivisions: usize) -> Result<Wall, HybridError> {
    Wall::nested(&ellipsoid_surface(inner, subdivisions), &ellipsoid_surface(outer, subdivisions))
}

/// The synthetic truncated ventricle (`PROTOCOL.md`): the wall between the ellipsoids of `p`
/// above `z = p.z_cut`, as one closed surface tagged inner / outer / base, at the surface
/// resolution of `p` (circumferential x longitudinal points per surface).
pub fn truncated_ventricle(p: &TruncatedEllipsoidWall) -> Result<Wall, HybridError> {
    let mesh = try_truncated_ellipsoid_wall(&TruncatedEllipsoidWall { layers: 1, ..*p })?;
    let faces = mesh.boundary_faces();
    let pts = mesh.points();
    let level = |x: &crate::math::Vec3, a: [f64; 3]| ((x.x / a[0]).powi(2) + (x.y / a[1]).powi(2) + (x.z / a[2]).powi(2)).sqrt();
    let scale = p.outer[2];
    let parts: Vec<WallPart> = faces
        .iter()
        .map(|f| {
            if f.iter().all(|&v| (pts[v].z - p.z_cut).abs() <= 1e-9 * scale) {
                WallPart::Base
            } else {
                let c = (pts[f[0]] + pts[f[1]] + pts[f[2]]) / 3.0;
                if (level(&c, p.inner) - 1.0).abs() < (level(&c, p.outer) - 1.0).abs() {
                    WallPart::Inner
                } else {
                    WallPart::Outer
                }
            }
        })
        .collect();
    let arr: Vec<[f64; 3]> = pts.iter().map(|x| [x.x, x.y, x.z]).collect();
    let tri: Vec<[i64; 3]> = faces.iter().map(|f| [f[0] as i64, f[1] as i64, f[2] as i64]).collect();
    let (surface, _) = TriSurface::from_arrays(&arr, &tri)?;
    Wall::tagged(surface, parts)
}
