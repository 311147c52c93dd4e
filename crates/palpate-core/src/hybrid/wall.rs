//! The input of a build: the wall's closed boundary with a part (inner, outer, base) per triangle.

use super::transmural::WallPart;
use crate::error::HybridError;
use crate::math::Vec3;
use crate::mesh::TriSurface;
use std::collections::HashMap;

/// The input: the wall's closed boundary with a part per triangle.
#[derive(Debug, Clone)]
pub struct Wall {
    pub surface: TriSurface,
    pub parts: Vec<WallPart>,
    /// Tiny closed pieces dropped from a tagged surface.
    pub dropped_pieces: usize,
}

/// Smallest volume of a closed piece of a tagged wall surface, relative to the largest piece
/// ([`TriSurface::without_specks`]).
pub const MIN_PIECE_VOLUME: f64 = 1e-3;

/// One part of a wall as a surface of its own ([`Wall::part`]).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct PartSurface {
    pub points: Vec<Vec3>,
    pub tris: Vec<[usize; 3]>,
}

impl Wall {
    /// Two nested closed surfaces: the wall is the region inside `outer` and outside `inner`.
    pub fn nested(inner: &TriSurface, outer: &TriSurface) -> Result<Wall, HybridError> {
        for (v, p) in inner.points().iter().enumerate() {
            if !outer.contains_parity(p) {
                return Err(crate::mesh::SurfaceError::NotNested { vertex: v, x: p.x, y: p.y, z: p.z }.into());
            }
        }
        if outer.volume() <= inner.volume() {
            return Err(HybridError::Parts(format!("the inner surface encloses {:e} m^3, not less than the outer's {:e} m^3", inner.volume(), outer.volume())));
        }
        let n = outer.n_vertices();
        let mut pts: Vec<[f64; 3]> = outer.points().iter().map(|p| [p.x, p.y, p.z]).collect();
        pts.extend(inner.points().iter().map(|p| [p.x, p.y, p.z]));
        let mut tris: Vec<[i64; 3]> = outer.triangles().iter().map(|t| [t[0] as i64, t[1] as i64, t[2] as i64]).collect();
        // Inner triangles flipped: the wall's boundary faces away from the wall.
        tris.extend(inner.triangles().iter().map(|t| [(t[0] + n) as i64, (t[2] + n) as i64, (t[1] + n) as i64]));
        let mut parts = vec![WallPart::Outer; outer.n_triangles()];
        parts.extend(std::iter::repeat_n(WallPart::Inner, inner.n_triangles()));
        let (surface, _) = TriSurface::from_arrays(&pts, &tris)?;
        Ok(Wall { surface, parts, dropped_pieces: 0 })
    }

    /// One closed surface with a part per triangle (a truncated ventricle: inner, outer, base).
    /// Closed pieces enclosing less than [`MIN_PIECE_VOLUME`] of the largest (specks left by a
    /// surface repair) are dropped; [`Wall::dropped_pieces`] counts them.
    pub fn tagged(surface: TriSurface, parts: Vec<WallPart>) -> Result<Wall, HybridError> {
        if parts.len() != surface.n_triangles() {
            return Err(HybridError::Parts(format!("{} part tags for {} triangles", parts.len(), surface.n_triangles())));
        }
        let kept = surface.without_specks(MIN_PIECE_VOLUME)?;
        let parts: Vec<WallPart> = kept.kept.iter().map(|&t| parts[t]).collect();
        let (surface, dropped) = (kept.surface, kept.dropped);
        for need in [WallPart::Inner, WallPart::Outer] {
            if !parts.contains(&need) {
                return Err(HybridError::Parts(format!("no {need:?} triangles")));
            }
        }
        check_not_swapped(&surface, &parts)?;
        Ok(Wall { surface, parts, dropped_pieces: dropped })
    }

    /// The triangles of one part as a surface of its own.
    pub(super) fn part(&self, which: WallPart) -> PartSurface {
        let mut map = HashMap::new();
        let (mut points, mut tris) = (vec![], vec![]);
        for (t, tri) in self.surface.triangles().iter().enumerate() {
            if self.parts[t] != which {
                continue;
            }
            let mut nt = [0; 3];
            for (k, &v) in tri.iter().enumerate() {
                nt[k] = *map.entry(v).or_insert_with(|| {
                    points.push(self.surface.points()[v]);
                    points.len() - 1
                });
            }
            tris.push(nt);
        }
        PartSurface { points, tris }
    }
}

/// Swapped inner and outer tags are refused (they were accepted, and built a wall inside out).
/// With the wall's boundary oriented outward, the outer part's share of the enclosed volume
/// (`sum (a . (b x c)) / 6` from the surface's centroid) is positive and the inner part's, facing
/// the cavity, negative; swapped tags give the opposite signs.
fn check_not_swapped(surface: &TriSurface, parts: &[WallPart]) -> Result<(), HybridError> {
    let pts = surface.points();
    let centre = pts.iter().fold(crate::math::Vec3::zeros(), |a, p| a + p) / pts.len().max(1) as f64;
    let (mut inner, mut outer) = (0.0, 0.0);
    for (t, part) in surface.triangles().iter().zip(parts) {
        let [a, b, c] = t.map(|v| pts[v] - centre);
        let v = a.dot(&b.cross(&c)) / 6.0;
        match part {
            WallPart::Inner => inner += v,
            WallPart::Outer => outer += v,
            WallPart::Base => {}
        }
    }
    if outer < 0.0 && inner > 0.0 {
        return Err(HybridError::Parts(format!(
            "the inner and outer tags look swapped: the triangles tagged outer face the cavity (volume share {outer:.3e} m^3) and those tagged inner face outward ({inner:.3e} m^3); swap the inner and outer tag values"
        )));
    }
    Ok(())
}
