//! Walls that ship with palpate: the paper's two concentric ellipsoids and the synthetic
//! truncated ventricle of the benchmark protocol.

use super::build::Wall;
use super::transmural::WallPart;
use crate::error::HybridError;
use crate::mesh::generate::{truncated_ellipsoid_wall, TruncatedEllipsoidWall};
use crate::mesh::{ellipsoid_surface, TetMesh, TriSurface};
use std::collections::HashMap;

/// The paper's "Ellipsoids Model" wall: concentric ellipsoids of semi-axes `inner` and `outer`
/// \[m\], each an octahedron refined `subdivisions` times (`8 * 4^s` triangles).
pub fn ellipsoids(inner: [f64; 3], outer: [f64; 3], subdivisions: usize) -> Result<Wall, HybridError> {
    Wall::nested(&ellipsoid_surface(inner, subdivisions), &ellipsoid_surface(outer, subdivisions))
}

/// The outward-oriented boundary triangles of a tet mesh.
pub fn oriented_boundary(mesh: &TetMesh) -> Vec<[usize; 3]> {
    let mut seen: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    let p = mesh.points();
    for t in mesh.tets() {
        let [a, b, c, d] = *t;
        let pos = crate::mesh::signed_volume(&p[a], &p[b], &p[c], &p[d]) > 0.0;
        let faces = if pos { [[b, c, d], [a, d, c], [a, b, d], [a, c, b]] } else { [[b, d, c], [a, c, d], [a, d, b], [a, b, c]] };
        for f in faces {
            let mut k = f;
            k.sort_unstable();
            seen.entry(k).and_modify(|e| e.0 += 1).or_insert((1, f));
        }
    }
    let mut out: Vec<[usize; 3]> = seen.into_values().filter(|(n, _)| *n == 1).map(|(_, f)| f).collect();
    out.sort_unstable();
    out
}

/// The synthetic truncated ventricle (`PROTOCOL.md`): the wall between the ellipsoids of `p`
/// above `z = p.z_cut`, as one closed surface tagged inner / outer / base, at the surface
/// resolution of `p` (circumferential x longitudinal points per surface).
pub fn truncated_ventricle(p: &TruncatedEllipsoidWall) -> Result<Wall, HybridError> {
    let mesh = truncated_ellipsoid_wall(&TruncatedEllipsoidWall { layers: 1, ..*p });
    let faces = oriented_boundary(&mesh);
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
                if (level(&c, p.inner) - 1.0).abs() < (level(&c, p.outer) - 1.0).abs() { WallPart::Inner } else { WallPart::Outer }
            }
        })
        .collect();
    let arr: Vec<[f64; 3]> = pts.iter().map(|x| [x.x, x.y, x.z]).collect();
    let tri: Vec<[i64; 3]> = faces.iter().map(|f| [f[0] as i64, f[1] as i64, f[2] as i64]).collect();
    let (surface, _) = TriSurface::from_arrays(&arr, &tri)?;
    Wall::tagged(surface, parts)
}
