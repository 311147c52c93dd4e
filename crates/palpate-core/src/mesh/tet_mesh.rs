//! A validated mesh of linear tetrahedra.

use std::collections::HashMap;

use crate::error::MeshError;
use crate::math::Vec3;

/// A tet whose `|volume| / (longest edge)^3` is below this is refused as degenerate.
/// (A regular tet has 0.118; the benchmark meshes' worst is above 1e-2.)
pub const DEGENERATE_RELATIVE_VOLUME: f64 = 1e-6;

/// Something fixed during validation that the user should hear about.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshWarning {
    /// These tets had negative volume and were reoriented (nodes 2 and 3 swapped).
    Reoriented { tets: Vec<usize> },
}

impl std::fmt::Display for MeshWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MeshWarning::Reoriented { tets } => {
                let shown: Vec<String> = tets.iter().take(8).map(|t| t.to_string()).collect();
                let more = if tets.len() > 8 { format!(", ... ({} in all)", tets.len()) } else { String::new() };
                write!(f, "{} inverted tet(s) reoriented (swapped their last two nodes): {}{}", tets.len(), shown.join(", "), more)
            }
        }
    }
}

/// A tetrahedral mesh that passed validation: finite coordinates \[m\], indices in range, every
/// tet positively oriented with a non-degenerate volume, no duplicate tets and no unused nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct TetMesh {
    points: Vec<Vec3>,
    tets: Vec<[usize; 4]>,
}

/// Signed volume of the tet `(a, b, c, d)` (paper eq. 17) \[m^3\]; positive when `d` lies on the
/// side of `(a, b, c)` that their right-handed normal points to.
#[inline]
pub fn signed_volume(a: &Vec3, b: &Vec3, c: &Vec3, d: &Vec3) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// The signed volume of a tet and `|volume| / (longest edge)^3`, the measure the validator
/// refuses below [`DEGENERATE_RELATIVE_VOLUME`]: one function, so that the generators' checks
/// before building ([`super::generate`]) agree with [`TetMesh::from_arrays`] to the last bit.
#[inline]
pub(crate) fn volume_and_relative(a: &Vec3, b: &Vec3, c: &Vec3, d: &Vec3) -> (f64, f64) {
    let vol = signed_volume(a, b, c, d);
    let edges = [b - a, c - a, d - a, c - b, d - b, d - c];
    let lmax = edges.iter().map(|e| e.norm()).fold(0.0, f64::max);
    let relative = if lmax > 0.0 { vol.abs() / (lmax * lmax * lmax) } else { 0.0 };
    (vol, relative)
}

/// For each node the lowest-numbered node at exactly the same position, or None when no two nodes
/// coincide (the usual case: then a node is its own). By sorting the nodes by their coordinates'
/// bits (`+ 0.0` makes -0.0 the same corner as 0.0): one sort, no hashing, no table kept when
/// every position is distinct.
fn coincident_nodes(pts: &[Vec3]) -> Option<Vec<usize>> {
    let keys: Vec<[u64; 3]> = pts.iter().map(|p| [p.x, p.y, p.z].map(|c| (c + 0.0).to_bits())).collect();
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_unstable_by_key(|&i| (keys[i], i));
    if order.windows(2).all(|w| keys[w[0]] != keys[w[1]]) {
        return None;
    }
    let mut canonical: Vec<usize> = (0..pts.len()).collect();
    // Within a run of equal keys the order is by node number: its first is the lowest.
    for run in order.chunk_by(|&a, &b| keys[a] == keys[b]) {
        for &i in run {
            canonical[i] = run[0];
        }
    }
    Some(canonical)
}

impl TetMesh {
    /// Validate a mesh given as points `(n_nodes, 3)` \[m\] and tets `(n_tets, 4)` node indices
    /// (signed, so that negative indices from a file are reported rather than wrapped).
    pub fn from_arrays(points: &[[f64; 3]], tets: &[[i64; 4]]) -> Result<(TetMesh, Vec<MeshWarning>), MeshError> {
        if points.is_empty() {
            return Err(MeshError::Empty { what: "no nodes" });
        }
        if tets.is_empty() {
            return Err(MeshError::Empty { what: "no tetrahedra" });
        }
        let n = points.len();
        let pts = super::finite_points(points).map_err(|i| {
            let p = points[i];
            MeshError::NonFiniteNode { node: i, x: p[0], y: p[1], z: p[2] }
        })?;
        let mut out = Vec::with_capacity(tets.len());
        let mut reoriented = Vec::new();
        let mut used = vec![false; n];
        let mut seen: HashMap<[usize; 4], usize> = HashMap::with_capacity(tets.len());
        // A tet repeated on copied nodes (the same corners under other node numbers) is a
        // duplicate too: key the tets by the first node at each corner's position, so that
        // exactly coincident nodes share a key (a mesh written twice into one file, or merged
        // without welding, doubled the volume and mass there without a word).
        let canonical = coincident_nodes(&pts);
        for (t, tet) in tets.iter().enumerate() {
            let mut idx = [0usize; 4];
            for k in 0..4 {
                let i = tet[k];
                if i < 0 || i as u64 >= n as u64 {
                    return Err(MeshError::IndexOutOfRange { tet: t, index: i, n_nodes: n });
                }
                idx[k] = i as usize;
            }
            for a in 0..4 {
                for b in a + 1..4 {
                    if idx[a] == idx[b] {
                        return Err(MeshError::RepeatedNode { tet: t, node: idx[a] });
                    }
                }
            }
            let [a, b, c, d] = idx.map(|i| pts[i]);
            let (vol, relative) = volume_and_relative(&a, &b, &c, &d);
            if !(relative >= DEGENERATE_RELATIVE_VOLUME) {
                return Err(MeshError::Degenerate { tet: t, volume: vol, relative });
            }
            if vol < 0.0 {
                idx.swap(2, 3);
                reoriented.push(t);
            }
            let mut key = canonical.as_ref().map_or(idx, |c| idx.map(|i| c[i]));
            key.sort_unstable();
            if let Some(&other) = seen.get(&key) {
                let first = out.get(other).copied().unwrap_or(idx);
                let same_nodes = {
                    let (mut a, mut b) = (idx, first);
                    a.sort_unstable();
                    b.sort_unstable();
                    a == b
                };
                return Err(if same_nodes {
                    MeshError::DuplicateTet { tet: t, other }
                } else {
                    MeshError::CoincidentTet { tet: t, other, nodes: idx, other_nodes: first }
                });
            }
            seen.insert(key, t);
            for &i in &idx {
                used[i] = true;
            }
            out.push(idx);
        }
        if let Some(node) = used.iter().position(|u| !u) {
            return Err(MeshError::UnusedNode { node });
        }
        let warnings = if reoriented.is_empty() { vec![] } else { vec![MeshWarning::Reoriented { tets: reoriented }] };
        Ok((TetMesh { points: pts, tets: out }, warnings))
    }

    /// Node positions \[m\], `(n_nodes)`.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }
    /// Tets as node indices, `(n_tets, 4)`, positively oriented.
    pub fn tets(&self) -> &[[usize; 4]] {
        &self.tets
    }
    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.points.len()
    }
    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.tets.len()
    }

    /// Total volume \[m^3\].
    pub fn volume(&self) -> f64 {
        self.tets
            .iter()
            .map(|t| {
                let [a, b, c, d] = t.map(|i| self.points[i]);
                signed_volume(&a, &b, &c, &d)
            })
            .sum()
    }

    /// Boundary faces (triangles used by exactly one tet), oriented outward, `(n_faces, 3)`,
    /// sorted ([`boundary_faces`]).
    pub fn boundary_faces(&self) -> Vec<[usize; 3]> {
        boundary_faces(&self.points, &self.tets)
    }
    /// Every edge once, lower vertex first, in the order of first appearance over the tets and
    /// their local edges `(0,1) (1,2) (0,2) (0,3) (1,3) (2,3)` (the order of a quadratic body's
    /// edge nodes, [`crate::fem::tet10::TET10_EDGES`]).
    pub fn edges(&self) -> Vec<[usize; 2]> {
        let mut seen = std::collections::HashSet::new();
        let mut out = Vec::new();
        for t in &self.tets {
            for [i, j] in crate::fem::tet10::TET10_EDGES {
                let e = [t[i].min(t[j]), t[i].max(t[j])];
                if seen.insert(e) {
                    out.push(e);
                }
            }
        }
        out
    }

    /// Minimum dihedral angle over all tets \[degrees\]: a quality measure.
    pub fn min_dihedral_deg(&self) -> f64 {
        let mut best = f64::INFINITY;
        for t in &self.tets {
            let p = t.map(|i| self.points[i]);
            // For each edge (i, j), the two faces meeting on it are those opposite the other nodes k, l.
            for (i, j, k, l) in [(0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1)] {
                let e = (p[j] - p[i]).normalize();
                let a = p[k] - p[i];
                let b = p[l] - p[i];
                let a = a - e * e.dot(&a);
                let b = b - e * e.dot(&b);
                let c = (a.dot(&b) / (a.norm() * b.norm())).clamp(-1.0, 1.0);
                best = best.min(c.acos().to_degrees());
            }
        }
        best
    }
}

/// The boundary faces of tets over `points` (triangles used by exactly one tet), each oriented
/// outward from its tet whichever the tet's own orientation, sorted.
pub fn boundary_faces(points: &[Vec3], tets: &[[usize; 4]]) -> Vec<[usize; 3]> {
    // Faces of a positively oriented tet (0,1,2,3), each listed with its outward orientation;
    // a negative tet's faces are listed reversed.
    const FACES: [[usize; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    for t in tets {
        let positive = signed_volume(&points[t[0]], &points[t[1]], &points[t[2]], &points[t[3]]) > 0.0;
        for f in FACES {
            let tri = if positive { [t[f[0]], t[f[1]], t[f[2]]] } else { [t[f[0]], t[f[2]], t[f[1]]] };
            let mut key = tri;
            key.sort_unstable();
            count.entry(key).and_modify(|e| e.0 += 1).or_insert((1, tri));
        }
    }
    let mut faces: Vec<[usize; 3]> = count.into_values().filter(|(c, _)| *c == 1).map(|(_, tri)| tri).collect();
    faces.sort_unstable();
    faces
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tet() -> (Vec<[f64; 3]>, Vec<[i64; 4]>) {
        (vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], vec![[0, 1, 2, 3]])
    }

    #[test]
    fn valid_tet_passes() {
        let (p, t) = unit_tet();
        let (m, w) = TetMesh::from_arrays(&p, &t).unwrap();
        assert!(w.is_empty());
        assert!((m.volume() - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(m.boundary_faces().len(), 4);
        assert!((m.min_dihedral_deg() - 54.7356).abs() < 1e-3);
    }

    #[test]
    fn inverted_tet_is_reoriented_with_warning() {
        let (p, _) = unit_tet();
        let (m, w) = TetMesh::from_arrays(&p, &[[0, 2, 1, 3]]).unwrap();
        assert_eq!(w, vec![MeshWarning::Reoriented { tets: vec![0] }]);
        assert!(m.volume() > 0.0);
    }

    #[test]
    fn defects_are_named() {
        let (p, t) = unit_tet();
        assert!(matches!(TetMesh::from_arrays(&[], &t), Err(MeshError::Empty { .. })));
        assert!(matches!(TetMesh::from_arrays(&p, &[]), Err(MeshError::Empty { .. })));
        assert_eq!(TetMesh::from_arrays(&p, &[[0, 1, 2, 4]]).unwrap_err(), MeshError::IndexOutOfRange { tet: 0, index: 4, n_nodes: 4 });
        assert_eq!(TetMesh::from_arrays(&p, &[[0, 1, -1, 3]]).unwrap_err(), MeshError::IndexOutOfRange { tet: 0, index: -1, n_nodes: 4 });
        assert!(matches!(TetMesh::from_arrays(&p, &[[0, 1, 1, 3]]), Err(MeshError::RepeatedNode { tet: 0, node: 1 })));
        let mut flat = p.clone();
        flat[3] = [0.3, 0.3, 0.0];
        assert!(matches!(TetMesh::from_arrays(&flat, &t), Err(MeshError::Degenerate { tet: 0, .. })));
        let mut nan = p.clone();
        nan[2][1] = f64::NAN;
        assert!(matches!(TetMesh::from_arrays(&nan, &t), Err(MeshError::NonFiniteNode { node: 2, .. })));
        let mut extra = p.clone();
        extra.push([5.0, 5.0, 5.0]);
        assert_eq!(TetMesh::from_arrays(&extra, &t).unwrap_err(), MeshError::UnusedNode { node: 4 });
        assert!(matches!(TetMesh::from_arrays(&p, &[[0, 1, 2, 3], [1, 0, 2, 3]]), Err(MeshError::DuplicateTet { tet: 1, other: 0 })));
        // The same tet on copied nodes (issue 35 item 6): twice the volume, refused too.
        let twice: Vec<[f64; 3]> = p.iter().chain(p.iter()).copied().collect();
        assert!(matches!(TetMesh::from_arrays(&twice, &[[0, 1, 2, 3], [4, 6, 5, 7]]), Err(MeshError::CoincidentTet { tet: 1, other: 0, .. })));
        // -0.0 is the same corner as 0.0.
        let mut signed = twice.clone();
        signed[4] = [-0.0, -0.0, -0.0];
        assert!(matches!(TetMesh::from_arrays(&signed, &[[0, 1, 2, 3], [4, 5, 6, 7]]), Err(MeshError::CoincidentTet { .. })));
    }
}
