//! Fixed-radius neighbour search at rest: palpate's uniform cell grid against the k-d tree of the
//! `kiddo` crate (the issue asks which is faster), on particle sets of the paper's sizes: a
//! lattice of 0.9 mm spacing filling an ellipsoidal LV shell, radius 1.8 spacings.
//!
//! `cargo bench -p palpate-core --bench neighbors`
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use palpate_core::meshfree::neighbors::neighbours_within;
use palpate_core::Vec3;

/// Lattice points of spacing `s` in the shell between two ellipsoids, the nearest `n` to a probe.
fn shell(n: usize, s: f64) -> Vec<Vec3> {
    let (inner, outer) = ([0.020, 0.020, 0.035], [0.026, 0.026, 0.042]);
    let level = |p: &Vec3, a: [f64; 3]| (p.x / a[0]).powi(2) + (p.y / a[1]).powi(2) + (p.z / a[2]).powi(2);
    let mut pts = Vec::new();
    let m = (outer[2] / s).ceil() as i64;
    for k in 0..=m {
        for j in -m..=m {
            for i in -m..=m {
                let p = Vec3::new(i as f64, j as f64, k as f64) * s;
                if level(&p, outer) < 1.0 && level(&p, inner) > 1.0 {
                    pts.push(p);
                }
            }
        }
    }
    let probe = Vec3::new(0.0229, 0.0, 0.02);
    pts.sort_by(|a, b| (a - probe).norm().total_cmp(&(b - probe).norm()));
    pts.truncate(n);
    pts
}

/// The same neighbour lists (CSR, sorted) from a k-d tree.
fn kdtree_neighbours(points: &[Vec3], radius: f64) -> (Vec<usize>, Vec<usize>) {
    let entries: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&entries).expect("k-d tree");
    let mut ptr = vec![0];
    let mut idx = Vec::new();
    for (i, e) in entries.iter().enumerate() {
        let mut row: Vec<usize> = tree
            .query(e)
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .exclusive_boundaries()
            .unsorted()
            .execute()
            .into_iter()
            .map(|r| r.item as usize)
            .filter(|&j| j != i)
            .collect();
        row.sort_unstable();
        idx.extend_from_slice(&row);
        ptr.push(idx.len());
    }
    (ptr, idx)
}

fn bench(c: &mut Criterion) {
    let s = 0.9e-3;
    let r = 1.8 * s;
    let mut g = c.benchmark_group("neighbours_at_rest");
    g.sample_size(10);
    for n in [600usize, 2000, 28000] {
        let pts = shell(n, s);
        assert_eq!(neighbours_within(&pts, r), kdtree_neighbours(&pts, r), "grid and k-d tree disagree");
        g.bench_with_input(BenchmarkId::new("cell_grid", n), &pts, |b, p| b.iter(|| neighbours_within(p, r)));
        g.bench_with_input(BenchmarkId::new("kiddo_kdtree", n), &pts, |b, p| b.iter(|| kdtree_neighbours(p, r)));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
