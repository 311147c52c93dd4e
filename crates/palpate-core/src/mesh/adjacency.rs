//! Adjacency of a triangle surface: the triangles around each vertex, the triangle across each
//! edge, and patches grown from a vertex by rings of triangles (the activation regions nv(p_s)
//! of the hybrid model, paper §4) with their boundary loops.

use crate::spatial::Buckets;

/// The triangles already in a patch: one flag per triangle (the builder's sweep over every
/// vertex; all false on entry and on exit), or a sorted list (one region on demand, a few hundred
/// triangles, without touching a flag per surface triangle).
pub enum Marks<'a> {
    Flags(&'a mut [bool]),
    Sorted(Vec<u32>),
}

impl Marks<'_> {
    /// Mark `t`; false if it was marked already.
    fn insert(&mut self, t: u32) -> bool {
        match self {
            Marks::Flags(f) => !std::mem::replace(&mut f[t as usize], true),
            Marks::Sorted(v) => match v.binary_search(&t) {
                Ok(_) => false,
                Err(k) => {
                    v.insert(k, t);
                    true
                }
            },
        }
    }

    fn reset(&mut self, patch: &[u32]) {
        if let Marks::Flags(f) = self {
            patch.iter().for_each(|&t| f[t as usize] = false);
        }
    }
}

/// A patch of triangles grown from a vertex ([`SurfaceAdjacency::patch`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// Its triangles, sorted.
    pub triangles: Vec<u32>,
    /// Rings of triangles it took (1: the triangles around the vertex).
    pub rings: usize,
}

/// Adjacency of a triangle surface: the triangles around each vertex and the triangle across
/// each edge (`u32::MAX` on an open boundary).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceAdjacency {
    /// Triangles around vertex `v`: `vertex_tris.get(v)`, in increasing order.
    pub vertex_tris: Buckets,
    /// Per triangle and edge `k` (from corner `k` to `k + 1`): the triangle across it.
    pub across: Vec<[u32; 3]>,
}

impl SurfaceAdjacency {
    /// Of `tris` over `nv` vertices.
    pub fn new(nv: usize, tris: &[[usize; 3]]) -> SurfaceAdjacency {
        let vertex_tris = Buckets::build(nv, tris.len(), |t| tris[t]);
        let mut across = vec![[u32::MAX; 3]; tris.len()];
        let mut keyed: Vec<(usize, usize, u32, u8)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                keyed.push((a.min(b), a.max(b), t as u32, k as u8));
            }
        }
        keyed.sort_unstable();
        for w in keyed.windows(2) {
            if (w[0].0, w[0].1) == (w[1].0, w[1].1) {
                across[w[0].2 as usize][w[0].3 as usize] = w[1].2;
                across[w[1].2 as usize][w[1].3 as usize] = w[0].2;
            }
        }
        SurfaceAdjacency { vertex_tris, across }
    }

    fn around(&self, v: usize) -> &[u32] {
        self.vertex_tris.get(v)
    }

    /// The triangles within `rings` rings of vertex `s` (sorted), growing one ring at a time
    /// while `more(rings so far, triangles added)` says so when `rings` is `None`. Returns the
    /// patch and the rings used.
    pub fn patch(&self, tris: &[[usize; 3]], s: usize, rings: Option<usize>, mut in_patch: Marks<'_>, mut more: impl FnMut(usize, &[u32]) -> bool) -> Patch {
        let mut patch: Vec<u32> = Vec::new();
        for &t in self.around(s) {
            in_patch.insert(t);
            patch.push(t);
        }
        let mut ring_start = 0;
        let mut r = 1;
        loop {
            let go_on = match rings {
                Some(n) => r < n,
                None => more(r, &patch[ring_start..]),
            };
            if !go_on {
                break;
            }
            let ring_end = patch.len();
            for i in ring_start..ring_end {
                for &v in &tris[patch[i] as usize] {
                    for &t in self.around(v) {
                        if in_patch.insert(t) {
                            patch.push(t);
                        }
                    }
                }
            }
            if patch.len() == ring_end {
                break; // the whole surface
            }
            ring_start = ring_end;
            r += 1;
        }
        in_patch.reset(&patch);
        patch.sort_unstable();
        Patch { triangles: patch, rings: r }
    }

    /// Boundary vertices of a patch (sorted triangles), in the order its directed boundary
    /// edges chain (other loops' vertices, if any, appended unordered).
    pub fn rim(&self, tris: &[[usize; 3]], patch: &[u32]) -> Vec<u32> {
        let inside = |t: u32| patch.binary_search(&t).is_ok();
        let mut next: Vec<(u32, u32)> = Vec::new();
        for &t in patch {
            let tri = tris[t as usize];
            for k in 0..3 {
                let o = self.across[t as usize][k];
                if o == u32::MAX || !inside(o) {
                    next.push((tri[k] as u32, tri[(k + 1) % 3] as u32));
                }
            }
        }
        next.sort_unstable();
        let mut loop_v: Vec<u32> = Vec::new();
        if let Some(&(start, _)) = next.first() {
            let mut v = start;
            for _ in 0..next.len() {
                loop_v.push(v);
                match next.binary_search_by_key(&v, |e| e.0) {
                    Ok(k) if next[k].1 != start => v = next[k].1,
                    _ => break,
                }
            }
            let mut seen = loop_v.clone();
            seen.sort_unstable();
            let mut rest: Vec<u32> = next.iter().map(|e| e.0).filter(|v| seen.binary_search(v).is_err()).collect();
            rest.dedup();
            loop_v.extend(rest);
        }
        loop_v
    }
}
