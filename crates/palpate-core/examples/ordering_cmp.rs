//! Compare orderings by factor fill: `cargo run --release --example ordering_cmp -- 1350`.
#[path = "../tests/support/protocol.rs"]
mod protocol;
use palpate_core::linalg::{ordering, Ldl};
use std::time::Instant;
fn block_fill(adj: &[Vec<usize>], order: &[usize]) -> usize {
    let n = adj.len();
    let mut pos = vec![0; n];
    for (k, &i) in order.iter().enumerate() {
        pos[i] = k;
    }
    let mut cols: Vec<Vec<usize>> = vec![vec![]; n];
    for i in 0..n {
        cols[pos[i]].push(pos[i]);
        for &j in &adj[i] {
            if pos[j] < pos[i] {
                cols[pos[i]].push(pos[j]);
            }
        }
    }
    let mut ap = vec![0];
    let mut ai = vec![];
    for c in cols {
        ai.extend(c);
        ap.push(ai.len());
    }
    Ldl::symbolic(n, ap, ai).nnz_l()
}
fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "1350".into());
    let case = protocol::load_case(&name).unwrap();
    let pts = case.mesh.points();
    let fixed: std::collections::HashSet<usize> = case.fixed.iter().copied().collect();
    let free: Vec<usize> = (0..pts.len()).filter(|i| !fixed.contains(i)).collect();
    let mut idx = vec![usize::MAX; pts.len()];
    for (k, &i) in free.iter().enumerate() {
        idx[i] = k;
    }
    let mut adj = vec![vec![]; free.len()];
    for t in case.mesh.tets() {
        for &a in t {
            for &b in t {
                if a != b && idx[a] != usize::MAX && idx[b] != usize::MAX {
                    adj[idx[a]].push(idx[b]);
                }
            }
        }
    }
    for a in adj.iter_mut() {
        a.sort_unstable();
        a.dedup();
    }
    let coords: Vec<_> = free.iter().map(|&i| pts[i]).collect();
    let t = Instant::now();
    let md = ordering::minimum_degree(&adj);
    let tmd = t.elapsed().as_secs_f64();
    println!("MD: block nnzL {} ({:.3}s)", block_fill(&adj, &md), tmd);
    for leaf in [32, 64, 128, 256, 500] {
        let t = Instant::now();
        let nd = ordering::nested_dissection(&adj, &coords, leaf);
        let tnd = t.elapsed().as_secs_f64();
        println!("ND leaf {leaf}: block nnzL {} ({:.3}s)", block_fill(&adj, &nd), tnd);
    }
}
