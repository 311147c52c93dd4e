//! The model's storage order, the build's last stage: the outer vertices in Morton order, the
//! outer triangles in the Morton order of their centroids, and the particles grouped by their
//! triangle in that order ([`crate::spatial::morton`]). A relabelling only: the same model
//! (every region, owner, tie and skin link the same), its neighbourhoods stored close together.
//!
//! Why: the particles are stored grouped by the outer triangle above them, in the triangles'
//! order, and a surface read from a file may list its triangles in any order. The Rodero et al.
//! ventricle's did: a 400-particle ball of its shell spanned 24,600 of its 28,039 particle
//! indices (108 pages of a per-particle array of 96 bytes; 21 after this stage), and its hybrid
//! tick takes 27% less time at ~400 active particles in this order, 18% less at ~200
//! (docs/history/benchmarks-log.md#fifth-session-2026-11-26-the-models-storage-order--18-and--27-on-rodero).
//! The builder's own stages keep the input's order, so their ties (a voxel as
//! near to two triangles) resolve as before: sorting the triangles first gave a slightly
//! different model (see `runtime/stability.rs` for what that showed).

use super::model::HybridModel;
use super::region_field::VOXEL_CORE;
use crate::math::Vec3;
use crate::spatial::{csr, morton};

/// Relabels `m`'s outer vertices, outer triangles and particles in Morton order.
pub(super) fn apply(m: &mut HybridModel) {
    let by_vertex = morton::order(&m.outer_points);
    let p = &m.outer_points;
    let centroids: Vec<Vec3> = m.outer_tris.iter().map(|t| (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0).collect();
    let by_tri = morton::order(&centroids);
    relabel(m, &by_vertex, &by_tri);
}

/// Lists `m`'s outer vertices in the order `by_vertex` and its outer triangles in the order
/// `by_tri` (`by_x[new] = old`), every index into them renamed, and its particles grouped by
/// their triangle's new index (in their old order within a group).
fn relabel(m: &mut HybridModel, by_vertex: &[usize], by_tri: &[usize]) {
    let new_vertex = inverse(by_vertex);
    m.outer_points = gather(&m.outer_points, by_vertex);
    m.region_rings = gather(&m.region_rings, by_vertex);
    m.region_box = gather(&m.region_box, by_vertex);
    m.skin_face = gather(&m.skin_face, by_vertex);
    m.skin_bary = gather(&m.skin_bary, by_vertex);
    m.skin_offset = gather(&m.skin_offset, by_vertex);
    let new_tri = inverse(by_tri);
    m.outer_tris = by_tri.iter().map(|&t| m.outer_tris[t].map(|v| new_vertex[v])).collect();
    for o in m.voxel_owner.iter_mut() {
        if *o < VOXEL_CORE {
            *o = new_tri[*o as usize] as u32;
        }
    }
    let mut by_particle: Vec<usize> = (0..m.particles.len()).collect();
    by_particle.sort_by_key(|&q| new_tri[m.particle_outer_tri[q] as usize]);
    m.particles = gather(&m.particles, &by_particle);
    m.particle_mass = gather(&m.particle_mass, &by_particle);
    m.particle_core_face = gather(&m.particle_core_face, &by_particle);
    m.particle_outer_tri = by_particle.iter().map(|&q| new_tri[m.particle_outer_tri[q] as usize] as u32).collect();
    m.tri_particle_ptr = csr::offsets(m.outer_tris.len(), m.particle_outer_tri.iter().map(|&t| t as usize));
    super::outer::derive(m);
}

/// `new[old]` for the order `order` (`order[new] = old`).
fn inverse(order: &[usize]) -> Vec<usize> {
    let mut new = vec![0; order.len()];
    for (k, &i) in order.iter().enumerate() {
        new[i] = k;
    }
    new
}

fn gather<T: Clone>(items: &[T], order: &[usize]) -> Vec<T> {
    order.iter().map(|&i| items[i].clone()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hybrid::{build, shapes, HybridOptions};
    use crate::material::{Damping, Elasticity};
    use crate::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
    use crate::Material;

    fn shuffled(n: usize, mut s: u64) -> Vec<usize> {
        let mut v: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            v.swap(i, (s >> 33) as usize % (i + 1));
        }
        v
    }

    fn bits(p: &Vec3) -> [u64; 3] {
        [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
    }

    /// What a wrong relabelling would do: rename an array's entries and not the indices into it
    /// (a region would list other particles, a voxel another triangle, a skin vertex another
    /// link), and the tick would then differ.
    #[test]
    fn a_relabelled_model_is_the_same_model() {
        let wall = shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 4).unwrap();
        let opts = HybridOptions { spacing: crate::hybrid::options::Spacing::Count(6000), ..HybridOptions::default() };
        let a = build(&wall, &opts).unwrap();
        let mut b = a.clone();
        let (by_vertex, by_tri) = (shuffled(a.outer_points.len(), 1), shuffled(a.outer_tris.len(), 2));
        relabel(&mut b, &by_vertex, &by_tri);
        assert_ne!(a.particles, b.particles, "the shuffle moved particles");
        let region = |m: &HybridModel, s: usize| {
            let mut v: Vec<[u64; 3]> = m.region_particle_ranges(s).into_iter().flatten().map(|q| bits(&m.particles[q])).collect();
            v.sort();
            v
        };
        for (new, &old) in by_vertex.iter().enumerate() {
            assert_eq!(b.outer_points[new], a.outer_points[old]);
            assert_eq!((b.region_rings[new], b.region_box[new]), (a.region_rings[old], a.region_box[old]));
            assert_eq!((b.skin_face[new], b.skin_bary[new], b.skin_offset[new]), (a.skin_face[old], a.skin_bary[old], a.skin_offset[old]));
            if new % 7 == 0 {
                assert_eq!(region(&b, new), region(&a, old), "region of vertex {old}");
            }
        }
        let corners = |m: &HybridModel, t: u32| {
            let mut c = m.outer_tris[t as usize].map(|v| bits(&m.outer_points[v]));
            c.sort();
            c
        };
        for (oa, ob) in a.voxel_owner.iter().zip(&b.voxel_owner) {
            if *oa < VOXEL_CORE {
                assert!(corners(&a, *oa) == corners(&b, *ob), "a voxel's owner changed");
            } else {
                assert_eq!(oa, ob);
            }
        }
        // Each particle keeps its mass, its core face and the triangle above it.
        let mut pa: Vec<_> = (0..a.particles.len())
            .map(|q| (bits(&a.particles[q]), a.particle_mass[q].to_bits(), a.particle_core_face[q], corners(&a, a.particle_outer_tri[q])))
            .collect();
        let mut pb: Vec<_> = (0..b.particles.len())
            .map(|q| (bits(&b.particles[q]), b.particle_mass[q].to_bits(), b.particle_core_face[q], corners(&b, b.particle_outer_tri[q])))
            .collect();
        pa.sort();
        pb.sort();
        assert!(pa == pb, "{} of {} particles' position, mass, core face or triangle differ", pa.iter().zip(&pb).filter(|(x, y)| x != y).count(), pa.len());
        // The same press gives the same force: to round-off, but sums running in another order
        // may tip a tick's sub-step count (a ceiling) by one, a difference of the integration's
        // order (a wrong relabelling moves the force by its own size).
        let mat = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
        let (sa, sb) = (Sim::new(a, mat, SimOptions::default()).unwrap(), Sim::new(b, mat, SimOptions::default()).unwrap());
        let top = *sa.hybrid.outer_points.iter().max_by(|p, q| p.x.total_cmp(&q.x)).unwrap();
        let r = sa.options.tool.radius;
        let (mut ta, mut wa, mut tb, mut wb) = (SimState::rest(&sa), SimWorkspace::new(&sa), SimState::rest(&sb), SimWorkspace::new(&sb));
        let (mut fmax, mut dmax) = (0.0f64, 0.0f64);
        for k in 0..150 {
            let c = top + Vec3::x() * (r - 3e-3 * (k.min(100) as f64 / 100.0));
            let (fa, fb) = (tick(&sa, &mut ta, &mut wa, c, 1e-3).unwrap(), tick(&sb, &mut tb, &mut wb, c, 1e-3).unwrap());
            assert_eq!(fa.active, fb.active, "tick {k}");
            assert!(fa.substeps.abs_diff(fb.substeps) <= 1, "tick {k}: {} vs {} sub-steps", fa.substeps, fb.substeps);
            fmax = fmax.max(fa.force.norm());
            dmax = dmax.max((fa.force - fb.force).norm());
        }
        assert!(dmax <= 1e-3 * fmax, "forces differ by up to {dmax} N of {fmax} N");
        assert!(fmax > 0.01, "the press reached the tissue: {fmax} N");
    }
}
