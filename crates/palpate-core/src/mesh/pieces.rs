//! A surface's closed pieces, and the surface without its specks.
//!
//! A repaired organ surface can hold tiny closed pieces beside the organ (Rodero's left ventricle
//! has two, of a few triangles, and they cross the main piece). A tet mesher refuses a surface
//! that crosses itself, and a wall's build would fill them as tissue; both want them gone. A
//! piece is a set of triangles connected through shared vertices; its volume is the signed
//! volume its triangles enclose (negative for an inward piece: a cavity, which is no speck).

use super::surface::{SurfaceError, TriSurface};

/// The pieces of a surface: a label per triangle and each piece's enclosed volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Pieces {
    /// The piece of each triangle, 0-based, numbered in the order of their first triangle.
    pub of_triangle: Vec<usize>,
    /// Each piece's signed enclosed volume \[m^3\] (negative: an inward piece, a cavity).
    pub volumes: Vec<f64>,
}

/// A surface without its specks ([`TriSurface::without_specks`]).
#[derive(Debug, Clone)]
pub struct WithoutSpecks {
    /// The pieces kept, their vertices renumbered in their original order.
    pub surface: TriSurface,
    /// The original index of each kept triangle (to carry per-triangle data such as a wall's parts).
    pub kept: Vec<usize>,
    /// Pieces dropped.
    pub dropped: usize,
}

fn find(up: &mut [usize], mut x: usize) -> usize {
    while up[x] != x {
        up[x] = up[up[x]];
        x = up[x];
    }
    x
}

impl TriSurface {
    /// The surface's vertex-connected pieces and their volumes.
    pub fn pieces(&self) -> Pieces {
        let (tris, pts) = (self.triangles(), self.points());
        // Union-find over vertices through triangles.
        let mut up: Vec<usize> = (0..self.n_vertices()).collect();
        for t in tris {
            let a = find(&mut up, t[0]);
            for &v in &t[1..] {
                let b = find(&mut up, v);
                up[b] = a;
            }
        }
        let mut label = vec![usize::MAX; self.n_vertices()];
        let (mut of_triangle, mut volumes) = (Vec::with_capacity(tris.len()), Vec::new());
        for t in tris {
            let root = find(&mut up, t[0]);
            if label[root] == usize::MAX {
                label[root] = volumes.len();
                volumes.push(0.0);
            }
            let piece = label[root];
            of_triangle.push(piece);
            volumes[piece] += pts[t[0]].dot(&pts[t[1]].cross(&pts[t[2]])) / 6.0;
        }
        Pieces { of_triangle, volumes }
    }

    /// This surface without the pieces enclosing less than `min_volume_fraction` of the largest
    /// piece's volume (by magnitude, so that a cavity is kept). `Parameter` error unless
    /// `0 <= min_volume_fraction < 1`.
    pub fn without_specks(&self, min_volume_fraction: f64) -> Result<WithoutSpecks, SurfaceError> {
        if !(0.0..1.0).contains(&min_volume_fraction) {
            return Err(SurfaceError::Parameter { name: "min_volume_fraction", value: min_volume_fraction, reason: "must be in [0, 1)" });
        }
        let Pieces { of_triangle, volumes } = self.pieces();
        let largest = volumes.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let keep: Vec<bool> = volumes.iter().map(|v| v.abs() >= min_volume_fraction * largest).collect();
        let dropped = keep.iter().filter(|&&k| !k).count();
        let kept: Vec<usize> = (0..of_triangle.len()).filter(|&t| keep[of_triangle[t]]).collect();
        if dropped == 0 {
            return Ok(WithoutSpecks { surface: self.clone(), kept, dropped });
        }
        let (tris, pts) = (self.triangles(), self.points());
        let mut map = vec![usize::MAX; self.n_vertices()];
        kept.iter().for_each(|&t| tris[t].iter().for_each(|&v| map[v] = 0));
        let mut new_pts = Vec::new();
        for (v, m) in map.iter_mut().enumerate() {
            if *m == 0 {
                *m = new_pts.len();
                new_pts.push([pts[v].x, pts[v].y, pts[v].z]);
            }
        }
        let new_tris: Vec<[i64; 3]> = kept.iter().map(|&t| tris[t].map(|v| map[v] as i64)).collect();
        // The kept pieces are closed, manifold and valid as they were: no new warning can arise.
        let (surface, _) = TriSurface::from_arrays(&new_pts, &new_tris)?;
        Ok(WithoutSpecks { surface, kept, dropped })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::ellipsoid_surface;

    /// Two surfaces' points and triangles as one surface, the second shifted by `shift` and
    /// flipped if `flip`.
    fn joined(a: &TriSurface, b: &TriSurface, shift: f64, flip: bool) -> TriSurface {
        let mut p: Vec<[f64; 3]> = a.points().iter().map(|v| [v.x, v.y, v.z]).collect();
        p.extend(b.points().iter().map(|v| [v.x + shift, v.y, v.z]));
        let n = a.n_vertices() as i64;
        let mut t: Vec<[i64; 3]> = a.triangles().iter().map(|t| t.map(|v| v as i64)).collect();
        t.extend(
            b.triangles()
                .iter()
                .map(|t| if flip { [t[0] as i64 + n, t[2] as i64 + n, t[1] as i64 + n] } else { t.map(|v| v as i64 + n) }),
        );
        TriSurface::from_arrays(&p, &t).unwrap().0
    }

    #[test]
    fn a_speck_is_dropped_a_cavity_kept() {
        let big = ellipsoid_surface([0.02, 0.02, 0.03], 2);
        let speck = ellipsoid_surface([1e-4, 1e-4, 1e-4], 0);
        // The speck first, crossing nothing: its triangles are the first ones.
        let s = joined(&speck, &big, 0.0, false);
        let pieces = s.pieces();
        assert_eq!(pieces.volumes.len(), 2);
        assert!((pieces.volumes[0] - speck.volume()).abs() < 1e-12 * big.volume());
        assert!((pieces.volumes[1] - big.volume()).abs() < 1e-9 * big.volume());
        let w = s.without_specks(1e-3).unwrap();
        assert_eq!((w.dropped, w.surface.n_triangles(), w.surface.n_vertices()), (1, big.n_triangles(), big.n_vertices()));
        assert_eq!(w.kept, (speck.n_triangles()..s.n_triangles()).collect::<Vec<_>>());
        assert_eq!(w.surface.points(), big.points());
        assert_eq!(w.surface.triangles(), big.triangles());
        // Nothing is dropped at fraction 0, nor from one piece.
        assert_eq!(s.without_specks(0.0).unwrap().dropped, 0);
        assert_eq!(big.without_specks(0.5).unwrap().dropped, 0);
        // A hollow wall (an inward piece inside) keeps its cavity: it is no speck.
        let inner = ellipsoid_surface([0.015, 0.015, 0.025], 2);
        let wall = joined(&big, &inner, 0.0, true);
        let pieces = wall.pieces();
        assert!(pieces.volumes[1] < 0.0);
        assert_eq!(wall.without_specks(1e-3).unwrap().dropped, 0);
        // A nonsense fraction is refused by name.
        for bad in [f64::NAN, -0.1, 1.0, f64::INFINITY] {
            assert!(matches!(s.without_specks(bad), Err(SurfaceError::Parameter { name: "min_volume_fraction", .. })), "{bad}");
        }
    }
}
