//! Fill-reducing orderings of the free-node graph for the sparse LDL^T factorisation.
//!
//! Orderings work on nodes (3x3 blocks), which is 27 times cheaper than on scalar unknowns and
//! keeps each node's three unknowns together.
//!
//! * [`minimum_degree`]: the classic greedy minimum-degree ordering on the explicit elimination
//!   graph (Tinney-Walker / George-Liu). Good fill, cost grows with the fronts: used for small graphs.
//! * [`nested_dissection`]: geometric nested dissection (recursive coordinate bisection with
//!   vertex separators, George 1973) with minimum degree on the leaves: near-optimal fill for 3D
//!   meshes at `O(n log n)` cost, used for larger graphs.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::math::Vec3;

/// Graphs with more nodes than this are ordered by nested dissection.
pub const MINIMUM_DEGREE_MAX_NODES: usize = 2000;

/// An elimination order (`order[k]` = the node eliminated k-th) of the graph `adj`
/// (symmetric adjacency lists, self loops ignored), with node positions `coords` for dissection.
pub fn fill_reducing_order(adj: &[Vec<usize>], coords: &[Vec3]) -> Vec<usize> {
    if adj.len() <= MINIMUM_DEGREE_MAX_NODES {
        minimum_degree(adj)
    } else {
        nested_dissection(adj, coords, MINIMUM_DEGREE_MAX_NODES / 4)
    }
}

/// Sorted union of `a` and `b` without `skip1`, `skip2`, into `out`.
fn merge_without(a: &[usize], b: &[usize], skip1: usize, skip2: usize, out: &mut Vec<usize>) {
    out.clear();
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        let x = if j >= b.len() || (i < a.len() && a[i] < b[j]) {
            i += 1;
            a[i - 1]
        } else if i >= a.len() || b[j] < a[i] {
            j += 1;
            b[j - 1]
        } else {
            i += 1;
            j += 1;
            a[i - 1]
        };
        if x != skip1 && x != skip2 {
            out.push(x);
        }
    }
}

/// Greedy minimum-degree order on the explicit elimination graph.
pub fn minimum_degree(adj: &[Vec<usize>]) -> Vec<usize> {
    let n = adj.len();
    let mut g: Vec<Vec<usize>> = adj
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let mut v: Vec<usize> = a.iter().copied().filter(|&j| j != i).collect();
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect();
    let mut heap: BinaryHeap<Reverse<(usize, usize)>> = (0..n).map(|i| Reverse((g[i].len(), i))).collect();
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    let mut scratch = Vec::new();
    while let Some(Reverse((d, v))) = heap.pop() {
        if done[v] || d != g[v].len() {
            continue; // stale heap entry
        }
        done[v] = true;
        order.push(v);
        let nb = std::mem::take(&mut g[v]);
        // Eliminating v makes its neighbours a clique.
        for &u in &nb {
            merge_without(&g[u], &nb, u, v, &mut scratch);
            std::mem::swap(&mut g[u], &mut scratch);
            heap.push(Reverse((g[u].len(), u)));
        }
    }
    order
}

/// Geometric nested dissection: split the nodes at the median of their widest coordinate, take
/// the nodes of the lower half that touch the upper half as the separator, order both halves
/// recursively and the separator last. Parts of at most `leaf` nodes use [`minimum_degree`].
pub fn nested_dissection(adj: &[Vec<usize>], coords: &[Vec3], leaf: usize) -> Vec<usize> {
    let n = adj.len();
    let mut order = Vec::with_capacity(n);
    let mut part = vec![usize::MAX; n]; // scratch: label of the current subproblem
    let all: Vec<usize> = (0..n).collect();
    dissect(adj, coords, all, leaf.max(8), &mut part, &mut order, 0);
    debug_assert_eq!(order.len(), n);
    order
}

fn induced_subgraph(adj: &[Vec<usize>], nodes: &[usize], local: &mut [usize]) -> Vec<Vec<usize>> {
    for (k, &i) in nodes.iter().enumerate() {
        local[i] = k;
    }
    let sub = nodes
        .iter()
        .map(|&i| adj[i].iter().filter(|&&j| local[j] != usize::MAX && nodes.get(local[j]) == Some(&j)).map(|&j| local[j]).collect())
        .collect();
    for &i in nodes {
        local[i] = usize::MAX;
    }
    sub
}

fn dissect(adj: &[Vec<usize>], coords: &[Vec3], mut nodes: Vec<usize>, leaf: usize, scratch: &mut Vec<usize>, order: &mut Vec<usize>, depth: usize) {
    if nodes.len() <= leaf || depth > 64 {
        let sub = induced_subgraph(adj, &nodes, scratch);
        order.extend(minimum_degree(&sub).into_iter().map(|k| nodes[k]));
        return;
    }
    // Widest axis of the bounding box.
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for &i in &nodes {
        lo = lo.inf(&coords[i]);
        hi = hi.sup(&coords[i]);
    }
    let axis = (hi - lo).imax();
    let mid = nodes.len() / 2;
    nodes.select_nth_unstable_by(mid, |&a, &b| coords[a][axis].total_cmp(&coords[b][axis]));
    // side: 1 = lower half, 2 = upper half, stored in scratch (usize::MAX = not in this part).
    for (k, &i) in nodes.iter().enumerate() {
        scratch[i] = if k < mid { 1 } else { 2 };
    }
    let mut left = Vec::with_capacity(mid);
    let mut right = Vec::with_capacity(nodes.len() - mid);
    let mut sep = Vec::new();
    for (k, &i) in nodes.iter().enumerate() {
        if k >= mid {
            right.push(i);
        } else if adj[i].iter().any(|&j| scratch[j] == 2) {
            sep.push(i);
        } else {
            left.push(i);
        }
    }
    for &i in &nodes {
        scratch[i] = usize::MAX;
    }
    if left.is_empty() || right.is_empty() {
        let sub = induced_subgraph(adj, &nodes, scratch);
        order.extend(minimum_degree(&sub).into_iter().map(|k| nodes[k]));
        return;
    }
    dissect(adj, coords, left, leaf, scratch, order, depth + 1);
    dissect(adj, coords, right, leaf, scratch, order, depth + 1);
    order.extend(sep);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize) -> (Vec<Vec<usize>>, Vec<Vec3>) {
        let id = |i: usize, j: usize| i + nx * j;
        let mut adj = vec![vec![]; nx * ny];
        let mut xy = vec![Vec3::zeros(); nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                xy[id(i, j)] = Vec3::new(i as f64, j as f64, 0.0);
                if i + 1 < nx {
                    adj[id(i, j)].push(id(i + 1, j));
                    adj[id(i + 1, j)].push(id(i, j));
                }
                if j + 1 < ny {
                    adj[id(i, j)].push(id(i, j + 1));
                    adj[id(i, j + 1)].push(id(i, j));
                }
            }
        }
        (adj, xy)
    }

    fn is_permutation(o: &[usize], n: usize) -> bool {
        let mut s = o.to_vec();
        s.sort_unstable();
        s == (0..n).collect::<Vec<_>>()
    }

    #[test]
    fn orders_are_permutations() {
        let (adj, xy) = grid(30, 20);
        assert!(is_permutation(&minimum_degree(&adj), 600));
        assert!(is_permutation(&nested_dissection(&adj, &xy, 16), 600));
    }

    #[test]
    fn minimum_degree_eliminates_a_path_from_its_ends() {
        // A path 0-1-2-3-4: the first eliminated node must be an end (degree 1).
        let adj = vec![vec![1], vec![0, 2], vec![1, 3], vec![2, 4], vec![3]];
        let o = minimum_degree(&adj);
        assert!(o[0] == 0 || o[0] == 4);
    }
}
