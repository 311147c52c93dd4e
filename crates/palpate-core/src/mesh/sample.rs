//! Filling a closed surface with particles on a regular cubic lattice.
//!
//! The lattice has spacing `s` and covers the surface's bounding box: along each axis
//! `n = ceil(extent / s)` points, centred on the box, so that when the extent is a whole number of
//! spacings the points sit half a spacing inside the box faces (and never on an axis-aligned face
//! of the surface). Each particle gets the mass of its lattice cell, `density * s^3`, so the total
//! mass is the density times the lattice's approximation of the volume.
//!
//! **Inside test.** One vertical line per lattice column `(x_i, y_j)`: its crossings with the
//! surface ([`TriSurface::column_crossings`], triangles bucketed by their xy bounding box, exact
//! tie-breaking through edges and vertices) are sorted, and the lattice points with an odd number
//! of crossings below them are inside. That costs `O(columns * triangles per column + points)`,
//! instead of `O(points * triangles)` for a point-by-point test. Should a column ever see an odd
//! number of crossings (it cannot for a validated closed surface, short of round-off in a
//! pathological mesh), its points fall back to the generalised winding number.

use super::surface::{SurfaceError, TriSurface};
use crate::math::Vec3;

/// Refuse lattices with more points than this (the spacing is too small for the surface).
pub const MAX_LATTICE_POINTS: f64 = 2e9;

/// Particles sampled from a solid: rest positions \[m\] and masses \[kg\].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ParticleSet {
    /// Positions \[m\].
    pub positions: Vec<Vec3>,
    /// Masses \[kg\]: `density * spacing^3` each.
    pub masses: Vec<f64>,
}

impl ParticleSet {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    /// No particles?
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// Total mass \[kg\].
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().sum()
    }
}

/// The lattice over a bounding box (see the module docs).
#[derive(Debug, Clone, Copy)]
struct Lattice {
    origin: Vec3,
    n: [usize; 3],
    s: f64,
}

impl Lattice {
    fn over(lo: Vec3, hi: Vec3, s: f64) -> Result<Lattice, SurfaceError> {
        let mut n = [0usize; 3];
        let mut origin = Vec3::zeros();
        let mut total = 1.0;
        for a in 0..3 {
            let k = ((hi[a] - lo[a]) / s - 1e-9).ceil().max(1.0);
            total *= k;
            if !(total <= MAX_LATTICE_POINTS) {
                return Err(SurfaceError::TooLarge { points: total, limit: MAX_LATTICE_POINTS });
            }
            n[a] = k as usize;
            if a == 2 {
                // Every lattice point may lie inside (a box): position and mass each, 32 bytes.
                crate::limits::check(&format!("sampling lattice of {total:.3e} points at spacing {s:e} m"), total, 32.0)?;
            }
            origin[a] = 0.5 * (lo[a] + hi[a]) - 0.5 * (k - 1.0) * s;
        }
        Ok(Lattice { origin, n, s })
    }

    fn x(&self, i: usize) -> f64 {
        self.origin.x + i as f64 * self.s
    }
    fn y(&self, j: usize) -> f64 {
        self.origin.y + j as f64 * self.s
    }
    fn z(&self, k: usize) -> f64 {
        self.origin.z + k as f64 * self.s
    }
}

fn check_params(spacing: f64, density: f64) -> Result<(), SurfaceError> {
    if !(spacing > 0.0 && spacing.is_finite()) {
        return Err(SurfaceError::Parameter { name: "spacing", value: spacing, reason: "must be positive and finite [m]" });
    }
    if !(density > 0.0 && density.is_finite()) {
        return Err(SurfaceError::Parameter { name: "density", value: density, reason: "must be positive and finite [kg/m^3]" });
    }
    Ok(())
}

/// Per-column inside classifier: sorted crossings, or the winding-number fallback.
struct Column<'a> {
    surface: &'a TriSurface,
    z: Vec<f64>,
    x: f64,
    y: f64,
    odd: bool,
    /// Index of the next crossing above the current height (heights are queried increasing).
    next: usize,
}

impl<'a> Column<'a> {
    fn new(surface: &'a TriSurface) -> Self {
        Column { surface, z: Vec::new(), x: 0.0, y: 0.0, odd: false, next: 0 }
    }

    fn reset(&mut self, x: f64, y: f64) {
        self.z.clear();
        self.surface.column_crossings(x, y, &mut self.z);
        self.z.sort_unstable_by(f64::total_cmp);
        (self.x, self.y, self.odd, self.next) = (x, y, self.z.len() % 2 == 1, 0);
    }

    /// Is `(x, y, z)` inside? `z` must not decrease between calls after a `reset`.
    fn inside(&mut self, z: f64) -> bool {
        if self.odd {
            return self.surface.contains(&Vec3::new(self.x, self.y, z));
        }
        while self.next < self.z.len() && self.z[self.next] < z {
            self.next += 1;
        }
        self.next % 2 == 1
    }

    /// The z range where this column may be inside.
    fn span(&self) -> Option<(f64, f64)> {
        if self.odd {
            let (lo, hi) = self.surface.bounding_box();
            return Some((lo.z, hi.z));
        }
        Some((*self.z.first()?, *self.z.last()?))
    }
}

fn fill(lattice: &Lattice, density: f64, mut keep: impl FnMut(f64, f64, &mut Vec<Vec3>)) -> ParticleSet {
    let mut positions = Vec::new();
    for i in 0..lattice.n[0] {
        for j in 0..lattice.n[1] {
            keep(lattice.x(i), lattice.y(j), &mut positions);
        }
    }
    let m = density * lattice.s * lattice.s * lattice.s;
    ParticleSet { masses: vec![m; positions.len()], positions }
}

/// Lattice indices `k` whose height lies in `[lo, hi]`.
///
/// The bounds are clamped to the lattice in floating point before the cast: a column crossing of
/// a near-degenerate triangle can lie far outside the bounding box (or be NaN), and a saturated
/// `usize` plus one overflows (found by the `tri_surface` fuzz target).
fn k_range(l: &Lattice, lo: f64, hi: f64) -> std::ops::Range<usize> {
    let n = l.n[2] as f64;
    // `as usize` maps NaN to 0: an empty range.
    let k0 = ((lo - l.origin.z) / l.s).floor().clamp(0.0, n) as usize;
    let k1 = (((hi - l.origin.z) / l.s).ceil() + 1.0).clamp(0.0, n) as usize;
    k0.min(k1)..k1
}

/// The points of a cubic lattice of spacing `spacing` \[m\] (see the module docs) that lie inside
/// `surface`, each of mass `density * spacing^3` \[kg\] (`density` in \[kg/m^3\]).
pub fn sample_inside(surface: &TriSurface, spacing: f64, density: f64) -> Result<ParticleSet, SurfaceError> {
    check_params(spacing, density)?;
    let (lo, hi) = surface.bounding_box();
    let l = Lattice::over(lo, hi, spacing)?;
    let mut col = Column::new(surface);
    Ok(fill(&l, density, |x, y, out| {
        col.reset(x, y);
        let Some((zlo, zhi)) = col.span() else { return };
        for k in k_range(&l, zlo, zhi) {
            let z = l.z(k);
            if col.inside(z) {
                out.push(Vec3::new(x, y, z));
            }
        }
    }))
}

/// The points of a cubic lattice of spacing `spacing` \[m\] over `outer`'s bounding box that lie
/// inside `outer` and not inside `inner` (a shell), each of mass `density * spacing^3` \[kg\].
///
/// Errors with [`SurfaceError::NotNested`] if a vertex of `inner` is not inside `outer`.
pub fn sample_between(inner: &TriSurface, outer: &TriSurface, spacing: f64, density: f64) -> Result<ParticleSet, SurfaceError> {
    check_params(spacing, density)?;
    let used = {
        let mut u = vec![false; inner.n_vertices()];
        inner.triangles().iter().flatten().for_each(|&i| u[i] = true);
        u
    };
    for (v, p) in inner.points().iter().enumerate() {
        if used[v] && !outer.contains_parity(p) {
            return Err(SurfaceError::NotNested { vertex: v, x: p.x, y: p.y, z: p.z });
        }
    }
    let (lo, hi) = outer.bounding_box();
    let l = Lattice::over(lo, hi, spacing)?;
    let (mut co, mut ci) = (Column::new(outer), Column::new(inner));
    Ok(fill(&l, density, |x, y, out| {
        co.reset(x, y);
        let Some((zlo, zhi)) = co.span() else { return };
        ci.reset(x, y);
        for k in k_range(&l, zlo, zhi) {
            let z = l.z(k);
            if co.inside(z) && !ci.inside(z) {
                out.push(Vec3::new(x, y, z));
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::super::surface::ellipsoid_surface;
    use super::*;
    use std::f64::consts::PI;
    use std::time::Instant;

    #[test]
    fn k_range_clamps_crossings_far_outside_the_lattice() {
        let l = Lattice { origin: Vec3::zeros(), n: [4, 4, 10], s: 0.1 };
        assert_eq!(k_range(&l, 0.25, 0.55), 2..7);
        // A crossing of a near-degenerate triangle can be huge, negative-huge or NaN.
        assert_eq!(k_range(&l, -1e300, 1e300), 0..10);
        assert_eq!(k_range(&l, 1e300, 1e300), 10..10);
        assert_eq!(k_range(&l, -1e300, -1e300), 0..0);
        assert!(k_range(&l, f64::NAN, f64::NAN).is_empty());
        assert_eq!(k_range(&l, f64::NEG_INFINITY, f64::INFINITY), 0..10);
    }

    #[test]
    fn sample_sphere_volume_converges() {
        let r = 0.02;
        let sphere = ellipsoid_surface([r, r, r], 6);
        let exact = 4.0 / 3.0 * PI * r * r * r;
        let mut errors = Vec::new();
        for div in [4.0, 8.0, 16.0, 32.0, 64.0] {
            let s = r / div;
            let set = sample_inside(&sphere, s, 1000.0).unwrap();
            let v = set.len() as f64 * s * s * s;
            let rel = (v - exact).abs() / exact;
            assert!((set.total_mass() - 1000.0 * v).abs() < 1e-9 * v * 1000.0);
            assert!(set.positions.iter().all(|p| p.norm() < r));
            errors.push(rel);
        }
        eprintln!("sphere fill: relative volume error at r/4 .. r/64: {:?}", errors.iter().map(|e| format!("{e:.2e}")).collect::<Vec<_>>());
        assert!(*errors.last().unwrap() < 0.02, "{errors:?}");
        // The error decreases with refinement (over each doubling pair, allowing lattice-count noise).
        for w in errors.windows(3) {
            assert!(w[2] < w[0], "{errors:?}");
        }
        assert!(errors[4] < errors[0] / 4.0, "{errors:?}");
    }

    #[test]
    fn sample_cube_lattice_is_offset_by_half_a_spacing() {
        let p: Vec<[f64; 3]> = (0..8).map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]).collect();
        let t = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        let cube = TriSurface::from_arrays(&p, &t).unwrap().0;
        let set = sample_inside(&cube, 0.1, 2.0).unwrap();
        assert_eq!(set.len(), 1000);
        assert!((set.total_mass() - 2.0).abs() < 1e-12);
        for q in &set.positions {
            for a in 0..3 {
                let f = q[a] / 0.1 - 0.5;
                assert!((f - f.round()).abs() < 1e-9 && q[a] > 0.0 && q[a] < 1.0, "{q:?}");
            }
        }
    }

    #[test]
    fn sample_between_shell_points_are_in_the_wall() {
        let inner = ellipsoid_surface([0.020, 0.020, 0.035], 3);
        let outer = ellipsoid_surface([0.026, 0.026, 0.042], 3);
        let set = sample_between(&inner, &outer, 2.5e-3, 1000.0).unwrap();
        assert!(set.len() > 1000, "{}", set.len());
        for p in &set.positions {
            assert!(outer.contains(p), "{p:?} not inside the outer surface");
            assert!(!inner.contains(p), "{p:?} inside the inner surface");
        }
        let v = set.len() as f64 * 2.5e-3f64.powi(3);
        let exact = outer.volume() - inner.volume();
        assert!((v - exact).abs() < 0.1 * exact, "{v:e} vs {exact:e}");
        // Not nested: swap the two.
        assert!(matches!(sample_between(&outer, &inner, 2.5e-3, 1000.0), Err(SurfaceError::NotNested { .. })));
        // Partly outside: a shifted inner surface.
        let shifted = {
            let p: Vec<[f64; 3]> = inner.points().iter().map(|v| [v.x + 0.01, v.y, v.z]).collect();
            let t: Vec<[i64; 3]> = inner.triangles().iter().map(|t| t.map(|i| i as i64)).collect();
            TriSurface::from_arrays(&p, &t).unwrap().0
        };
        let e = sample_between(&shifted, &outer, 2.5e-3, 1000.0).unwrap_err();
        assert!(e.to_string().starts_with("inner surface vertex "), "{e}");
    }

    #[test]
    fn sample_bad_parameters() {
        let s = ellipsoid_surface([1.0, 1.0, 1.0], 1);
        assert!(matches!(sample_inside(&s, 0.0, 1.0), Err(SurfaceError::Parameter { name: "spacing", .. })));
        assert!(matches!(sample_inside(&s, f64::NAN, 1.0), Err(SurfaceError::Parameter { name: "spacing", .. })));
        assert!(matches!(sample_inside(&s, 0.1, -1.0), Err(SurfaceError::Parameter { name: "density", .. })));
        assert!(matches!(sample_inside(&s, 1e-6, 1.0), Err(SurfaceError::TooLarge { .. })));
        // Coarser than the body: the one centre point.
        let one = sample_inside(&s, 10.0, 1.0).unwrap();
        assert_eq!(one.positions, vec![Vec3::zeros()]);
    }

    /// The left-ventricle-sized shell (paper's ellipsoid semi-axes) at 0.9 mm and at the spacing
    /// that gives about 28,000 particles; prints the timings (`cargo test -- --nocapture`).
    #[test]
    fn sample_lv_shell_is_fast() {
        let t0 = Instant::now();
        let inner = ellipsoid_surface([0.020, 0.020, 0.035], 5);
        let outer = ellipsoid_surface([0.026, 0.026, 0.042], 5);
        let t_surf = t0.elapsed().as_secs_f64();
        let exact = 4.0 / 3.0 * PI * (0.026 * 0.026 * 0.042 - 0.020 * 0.020 * 0.035);
        for s in [1.28e-3, 0.9e-3] {
            let t1 = Instant::now();
            let set = sample_between(&inner, &outer, s, 1000.0).unwrap();
            let dt = t1.elapsed().as_secs_f64();
            let v = set.len() as f64 * s * s * s;
            eprintln!(
                "LV shell fill at {:.2} mm: {} particles in {:.1} ms (surfaces: {} triangles each, built in {:.1} ms); volume {:+.2}% vs the ellipsoids",
                s * 1e3,
                set.len(),
                dt * 1e3,
                outer.n_triangles(),
                t_surf * 1e3,
                100.0 * (v - exact) / exact
            );
            assert!((v - exact).abs() < 0.03 * exact);
            assert!(dt < 2.0, "sampling took {dt} s");
        }
    }
}
