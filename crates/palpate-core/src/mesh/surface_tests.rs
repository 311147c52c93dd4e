//! Tests of [`super::TriSurface`]: validity, orientation, inside tests.
use super::*;
use std::f64::consts::PI;

/// The unit cube [0,1]^3, outward oriented (12 triangles).
fn cube() -> (Vec<[f64; 3]>, Vec<[i64; 3]>) {
    let p: Vec<[f64; 3]> = (0..8).map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]).collect();
    let t = vec![
        [0, 2, 1],
        [1, 2, 3], // z = 0 (normal -z)
        [4, 5, 6],
        [5, 7, 6], // z = 1
        [0, 1, 4],
        [1, 5, 4], // y = 0
        [2, 6, 3],
        [3, 6, 7], // y = 1
        [0, 4, 2],
        [2, 4, 6], // x = 0
        [1, 3, 5],
        [3, 7, 5], // x = 1
    ];
    (p, t)
}

/// A deterministic pseudo-random sequence in [0, 1) (xorshift).
fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed.max(1);
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn surface_cube_is_valid_with_unit_volume() {
    let (p, t) = cube();
    let (s, w) = TriSurface::from_arrays(&p, &t).unwrap();
    assert!(w.is_empty());
    assert!((s.volume() - 1.0).abs() < 1e-15);
    assert!((s.area() - 6.0).abs() < 1e-14);
    assert_eq!(s.bounding_box(), (Vec3::zeros(), Vec3::repeat(1.0)));
    assert!(s.contains(&Vec3::repeat(0.5)) && s.contains_parity(&Vec3::repeat(0.5)));
    assert!(!s.contains(&Vec3::new(1.5, 0.5, 0.5)) && !s.contains_parity(&Vec3::new(1.5, 0.5, 0.5)));
    assert!((s.winding_number(&Vec3::new(0.3, 0.6, 0.2)) - 1.0).abs() < 1e-12);
    assert!(s.winding_number(&Vec3::new(2.0, 0.6, 0.2)).abs() < 1e-12);
}

#[test]
fn surface_inward_orientation_is_reversed_with_warning() {
    let (p, mut t) = cube();
    for tri in t.iter_mut() {
        tri.swap(0, 1);
    }
    let (s, w) = TriSurface::from_arrays(&p, &t).unwrap();
    assert!(matches!(w.as_slice(), [SurfaceWarning::Reoriented { triangles: 12, volume }] if (*volume + 1.0).abs() < 1e-15));
    assert!((s.volume() - 1.0).abs() < 1e-15);
    assert!(s.contains(&Vec3::repeat(0.5)));
    assert!(w[0].to_string().contains("reversed all 12 triangles"));
}

#[test]
fn surface_unused_vertex_is_a_warning_and_ignored_in_the_box() {
    let (mut p, t) = cube();
    p.push([50.0, 50.0, 50.0]);
    let (s, w) = TriSurface::from_arrays(&p, &t).unwrap();
    assert_eq!(w, vec![SurfaceWarning::UnusedVertices { vertices: vec![8] }]);
    assert_eq!(s.bounding_box().1, Vec3::repeat(1.0));
}

#[test]
fn surface_malformed_cases_name_the_culprit() {
    let (p, t) = cube();
    let err = |p: &[[f64; 3]], t: &[[i64; 3]]| TriSurface::from_arrays(p, t).unwrap_err();

    assert_eq!(err(&[], &t), SurfaceError::Empty { what: "no vertices" });
    assert_eq!(err(&p, &[]), SurfaceError::Empty { what: "no triangles" });

    let mut q = p.clone();
    q[3][1] = f64::NAN;
    assert!(matches!(err(&q, &t), SurfaceError::NonFiniteVertex { vertex: 3, .. }));

    let mut u = t.clone();
    u[5][2] = 8;
    assert_eq!(err(&p, &u), SurfaceError::IndexOutOfRange { triangle: 5, index: 8, n_vertices: 8 });
    u[5][2] = -1;
    assert_eq!(err(&p, &u), SurfaceError::IndexOutOfRange { triangle: 5, index: -1, n_vertices: 8 });

    let mut u = t.clone();
    u[4] = [0, 1, 0];
    assert_eq!(err(&p, &u), SurfaceError::RepeatedVertex { triangle: 4, vertex: 0 });

    // A collinear triangle: vertex 8 at the midpoint of edge 0-1.
    let mut q = p.clone();
    q.push([0.5, 0.0, 0.0]);
    let mut u = t.clone();
    u.push([0, 8, 1]);
    assert!(matches!(err(&q, &u), SurfaceError::Degenerate { triangle: 12, .. }));

    let mut u = t.clone();
    u.push([2, 1, 3]);
    assert_eq!(err(&p, &u), SurfaceError::DuplicateTriangle { triangle: 12, other: 1 });

    // Open: remove one triangle of the top face.
    let mut u = t.clone();
    u.remove(2); // [4, 5, 6]
    let e = err(&p, &u);
    match &e {
        SurfaceError::OpenEdge { a, b, .. } => {
            let mut ab = [*a, *b];
            ab.sort();
            assert!([[4, 5], [4, 6], [5, 6]].contains(&ab), "{e}");
        }
        other => panic!("expected an open edge, got {other}"),
    }
    assert!(e.to_string().starts_with("open surface: edge ("));

    // Inconsistent orientation: flip one triangle.
    let mut u = t.clone();
    u[7].swap(0, 1);
    let e = err(&p, &u);
    assert!(matches!(e, SurfaceError::InconsistentOrientation { .. }), "{e}");
    assert!(e.to_string().contains("triangle 7"), "{e}");

    // Non-manifold: two fins hanging from the cube's edge (0, 1), which four triangles then share.
    let mut q = p.clone();
    q.push([0.5, -1.0, -1.0]);
    q.push([0.5, -1.0, -0.5]);
    let mut u = t.clone();
    u.push([0, 1, 8]);
    u.push([1, 0, 9]);
    let e = err(&q, &u);
    assert!(matches!(&e, SurfaceError::NonManifoldEdge { a: 0, b: 1, count: 4, .. }), "{e}");

    // Two cubes glued inside out so the volume cancels.
    let (mut q, mut u) = (p.clone(), t.clone());
    for v in &p {
        q.push([v[0] + 3.0, v[1], v[2]]);
    }
    for tri in &t {
        u.push([tri[0] + 8, tri[2] + 8, tri[1] + 8]);
    }
    assert!(matches!(err(&q, &u), SurfaceError::NoVolume { .. }));

    let e = err(&p, &[]).in_file("a.stl");
    assert_eq!(e.to_string(), "a.stl: empty surface: no triangles");
}

#[test]
fn surface_ellipsoid_volume_converges_to_analytic() {
    let axes = [0.026, 0.026, 0.042];
    let exact = 4.0 / 3.0 * PI * axes[0] * axes[1] * axes[2];
    let mut last = f64::INFINITY;
    for s in 0..=6 {
        let surf = ellipsoid_surface(axes, s);
        assert_eq!(surf.n_triangles(), 8 * 4usize.pow(s as u32));
        assert_eq!(surf.n_vertices(), 4 * 4usize.pow(s as u32) + 2);
        let v = surf.volume();
        assert!(v > 0.0 && v < exact);
        let rel = (exact - v) / exact;
        assert!(rel < last, "s = {s}: error {rel:e} did not decrease from {last:e}");
        if s >= 2 {
            // second order: the error drops ~4x per subdivision
            assert!(rel < 0.3 * last, "s = {s}: {rel:e} vs {last:e}");
        }
        last = rel;
    }
    assert!(last < 2e-3, "{last:e}");
    let (lo, hi) = ellipsoid_surface(axes, 3).bounding_box();
    assert!((hi - Vec3::from(axes)).norm() < 1e-15 && (lo + Vec3::from(axes)).norm() < 1e-15);
}

#[test]
fn surface_parity_and_winding_agree_on_random_points() {
    let surfaces = [ellipsoid_surface([0.02, 0.03, 0.05], 3), {
        let (p, t) = cube();
        TriSurface::from_arrays(&p, &t).unwrap().0
    }];
    for surf in &surfaces {
        let (lo, hi) = surf.bounding_box();
        let (lo, hi) = (lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo));
        let mut r = rng(42);
        let (mut inside, mut n) = (0, 0);
        for _ in 0..4000 {
            let p = Vec3::new(lo.x + r() * (hi.x - lo.x), lo.y + r() * (hi.y - lo.y), lo.z + r() * (hi.z - lo.z));
            let w = surf.winding_number(&p);
            assert!(w.abs() < 1e-9 || (w - 1.0).abs() < 1e-9, "winding number {w} at {p:?}");
            assert_eq!(surf.contains(&p), surf.contains_parity(&p), "{p:?}");
            inside += surf.contains(&p) as usize;
            n += 1;
        }
        assert!(inside > n / 10 && inside < n, "{inside} of {n}");
    }
}

#[test]
fn surface_parity_is_exact_through_vertices_and_edges() {
    // Lines through the octahedron's vertices and edges (x or y = 0) and the cube's edges
    // and corners (coordinates 0 or 1): simulation of simplicity gives an even count and the
    // right answer at every point off the surface.
    let oct = ellipsoid_surface([1.0, 1.0, 1.0], 2);
    let (p, t) = cube();
    let cube = TriSurface::from_arrays(&p, &t).unwrap().0;
    let mut z = Vec::new();
    for (surf, coords) in [(&oct, [-1.0, -0.5, 0.0, 0.5, 1.0]), (&cube, [0.0, 0.25, 0.5, 0.75, 1.0])] {
        for &x in &coords {
            for &y in &coords {
                z.clear();
                surf.column_crossings(x, y, &mut z);
                assert_eq!(z.len() % 2, 0, "column ({x}, {y}): {z:?}");
                for k in 0..41 {
                    let q = Vec3::new(x, y, -1.05 + 0.05 * k as f64 + 0.0123);
                    let w = surf.winding_number(&q);
                    let on_cube_face = std::ptr::eq(surf, &cube) && (x == 0.0 || x == 1.0 || y == 0.0 || y == 1.0) && (0.0..=1.0).contains(&q.z);
                    if (w - 0.5).abs() < 0.4 || on_cube_face {
                        continue; // on the surface
                    }
                    assert_eq!(surf.contains_parity(&q), w > 0.5, "({x}, {y}, {}) w = {w}", q.z);
                }
            }
        }
    }
}

#[test]
fn surface_nested_shell_with_inward_inner_part() {
    // Outer ellipsoid outward + inner ellipsoid inward: a valid closed surface of a shell.
    let outer = ellipsoid_surface([2.0, 2.0, 3.0], 2);
    let inner = ellipsoid_surface([1.0, 1.0, 2.0], 2);
    let nv = outer.n_vertices() as i64;
    let mut p: Vec<[f64; 3]> = outer.points().iter().map(|v| [v.x, v.y, v.z]).collect();
    p.extend(inner.points().iter().map(|v| [v.x, v.y, v.z]));
    let mut t: Vec<[i64; 3]> = outer.triangles().iter().map(|t| t.map(|i| i as i64)).collect();
    t.extend(inner.triangles().iter().map(|t| [t[0] as i64 + nv, t[2] as i64 + nv, t[1] as i64 + nv]));
    let (shell, w) = TriSurface::from_arrays(&p, &t).unwrap();
    assert!(w.is_empty());
    assert!((shell.volume() - (outer.volume() - inner.volume())).abs() < 1e-12);
    for q in [Vec3::zeros(), Vec3::new(0.0, 0.0, 2.5), Vec3::new(1.5, 0.0, 0.0), Vec3::new(3.0, 0.0, 0.0)] {
        assert_eq!(shell.contains(&q), shell.contains_parity(&q), "{q:?}");
    }
    assert!(!shell.contains(&Vec3::zeros()) && shell.contains(&Vec3::new(1.5, 0.0, 0.0)));
}
