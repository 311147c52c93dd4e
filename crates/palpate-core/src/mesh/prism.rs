//! Prisms cut into three tets, conformingly: the shells of the mesh generators
//! ([`super::generate`]) and the FEM core of the hybrid model are stacks of prisms (a triangle
//! of a surface and its copy one layer up), and the cut of each prism side (a quad) must agree
//! between the two prisms sharing it.
//!
//! The rule (Dompierre et al. 1999): every quadrilateral side takes the diagonal through its
//! smallest-index vertex. With the bottom triangle rotated so that its smallest index `v1` comes
//! first (orientation kept), `(v1 v2 v3)` below and `(v4 v5 v6)` above (`v4 = v1 + nv`, ...),
//! the sides over `v1 v2` and `v1 v3` take the diagonals from `v1`, which leaves the corner tet
//! `(v1 v5 v6 v4)` and a pyramid from `v1` over the quad `v2 v3 v6 v5`; that quad is cut by its
//! diagonal through `min(v2, v3)`: `(v1 v2 v3 v6) (v1 v2 v6 v5)` when `v2 < v3`, else
//! `(v1 v2 v3 v5) (v1 v5 v3 v6)`. The rule depends on each side's vertices alone, so
//! neighbouring prisms agree and the tets conform. For a triangle oriented counter-clockwise
//! seen from the top layer, the three tets are positively oriented in either [`TetOrder`].

/// The vertex order of the three tets (the same tets, with the same orientation, either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TetOrder {
    /// As in the module docs: each tet from `v1`, in the rotated frame (the hybrid core's).
    Rotated,
    /// Each tet from `v1`, its other three vertices rotated (an even permutation) so that the
    /// smallest comes first (the mesh generators').
    SmallestFirst,
}

/// The 3 tets of the prism over `bottom` (the top vertex of `v` is `v + nv`, `nv > 0`), cut by
/// the rule of the module docs.
pub fn split_prism(bottom: [usize; 3], nv: usize, order: TetOrder) -> [[usize; 4]; 3] {
    // Rotate so that the smallest index comes first (orientation kept).
    let m = (0..3).min_by_key(|&k| bottom[k]).unwrap();
    let (v1, v2, v3) = (bottom[m], bottom[(m + 1) % 3], bottom[(m + 2) % 3]);
    let (v4, v5, v6) = (v1 + nv, v2 + nv, v3 + nv);
    let mut tets = if v2.min(v6) < v3.min(v5) {
        [[v1, v2, v3, v6], [v1, v2, v6, v5], [v1, v5, v6, v4]]
    } else {
        [[v1, v2, v3, v5], [v1, v5, v3, v6], [v1, v5, v6, v4]]
    };
    if order == TetOrder::SmallestFirst {
        for t in &mut tets {
            let k = (1..4).min_by_key(|&k| t[k]).unwrap();
            t[1..].rotate_left(k - 1);
        }
    }
    tets
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The generators' former rule: vertices sorted, tets `(v0 v1 v2 v2') (v0 v1 v2' v1')
    /// (v0 v0' v1' v2')`, the last two nodes swapped when the sort was odd.
    fn generators_reference(tri: [usize; 3], lo: usize, hi: usize) -> [[usize; 4]; 3] {
        let (mut v, mut even) = (tri, true);
        for (a, b) in [(0, 1), (1, 2), (0, 1)] {
            if v[a] > v[b] {
                v.swap(a, b);
                even = !even;
            }
        }
        let [b0, b1, b2] = v.map(|i| lo + i);
        let [t0, t1, t2] = v.map(|i| hi + i);
        [[b0, b1, b2, t2], [b0, b1, t2, t1], [b0, t0, t1, t2]].map(|mut t| {
            if !even {
                t.swap(2, 3);
            }
            t
        })
    }

    #[test]
    fn both_orders_give_the_former_tets_exactly() {
        for nv in [3, 7, 40] {
            for l in 0..3 {
                for a in 0..nv.min(8) {
                    for b in 0..nv.min(8) {
                        for c in 0..nv.min(8) {
                            if a == b || b == c || a == c {
                                continue;
                            }
                            let tri = [a, b, c];
                            assert_eq!(
                                split_prism(tri.map(|i| i + l * nv), nv, TetOrder::SmallestFirst),
                                generators_reference(tri, l * nv, (l + 1) * nv),
                                "{tri:?} nv {nv} layer {l}"
                            );
                        }
                    }
                }
            }
        }
    }
}
