//! The quadratic (10-node) tetrahedron: the same continuum as [`super::tet4`] (Green strain, the
//! material's law, the viscous stress of the strain rate, paper §3.1) on quadratic shape
//! functions, integrated at four points.
//!
//! **Why.** Linear tets are constant-strain elements: a wall one or two of them thick cannot
//! bend without straining in shear, so it locks (VALIDATION.md, "Why a coarse core cannot carry
//! the wall": a 900-tet P1 wall is about twice too stiff against its own geometry, a P2 wall of
//! the same tets within about 10%; `tests/quadratic.rs`: a cantilever four elements long and one
//! across). The quadratic tet's strain is linear in the element, which is what bending needs.
//!
//! **Nodes.** The four vertices, then the six edge nodes in the order of [`TET10_EDGES`]. The
//! element is isoparametric: the rest map is interpolated by the same shape functions, so an
//! edge node moved off its midpoint (onto a curved surface) curves the element. Shape functions
//! in barycentric coordinates `L`: a vertex `L_i (2 L_i - 1)`, an edge `4 L_i L_j`.
//!
//! **Quadrature.** The 4-point rule of degree 2 (points at barycentric `(a, b, b, b)` and
//! permutations, `a = (5 + 3 sqrt 5) / 20`, weight a quarter of the volume each). The stiffness
//! of linear elasticity on a straight element is quadratic in `L`, so it is exact there; the
//! nonlinear laws are integrated as every FEM code integrates them, at the points. Every
//! quantity of the element is the sum over its points of the linear tet's formula with the
//! point's gradients `g_a = grad N_a` and weight `w` for the tet's gradients and volume:
//!
//! ```text
//! F = sum_a x_a g_a^T,   W = sum_q w_q psi(F_q),   f_a = -sum_q w_q (P_q + F_q S_v,q) g_qa,
//! ```
//!
//! so the forces are exactly minus the gradient of the energy (tested by finite differences),
//! sum to zero (the gradients of shape functions that sum to one sum to zero: linear momentum
//! is exact), and vanish for a rigid motion.
//!
//! **Mass.** Lumped by the HRZ rule (Hinton, Rock and Zienkiewicz 1976): the consistent mass's
//! diagonal scaled to the element's mass, a vertex `rho V / 36` and an edge node `4 rho V / 27`
//! (the row sums give the vertices a negative mass).

use super::tet4::svk_blocks;
use crate::material::{self, neo_hookean, Law, Material};
use crate::math::{Mat3, Vec3};

/// Local P2 edges, in the order of the nodes 4..9 (vertex pairs of the element).
pub const TET10_EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]];

/// The mass share of a vertex and of an edge node, over the element's mass (HRZ).
pub const VERTEX_MASS: f64 = 1.0 / 36.0;
pub const EDGE_MASS: f64 = 4.0 / 27.0;

/// Barycentric coordinates of the four quadrature points.
fn points() -> [[f64; 4]; 4] {
    let a = (5.0 + 3.0 * 5f64.sqrt()) / 20.0;
    let b = (5.0 - 5f64.sqrt()) / 20.0;
    [[a, b, b, b], [b, a, b, b], [b, b, a, b], [b, b, b, a]]
}

/// Derivatives `dN_a / dL_k` of the ten shape functions at barycentric point `l` `(10 x 4)`.
fn shape_derivatives(l: [f64; 4]) -> [[f64; 4]; 10] {
    let mut d = [[0.0; 4]; 10];
    for i in 0..4 {
        d[i][i] = 4.0 * l[i] - 1.0;
    }
    for (e, [i, j]) in TET10_EDGES.iter().enumerate() {
        d[4 + e][*i] = 4.0 * l[*j];
        d[4 + e][*j] = 4.0 * l[*i];
    }
    d
}

/// Values of the ten shape functions at barycentric point `l`.
pub fn shape_values(l: [f64; 4]) -> [f64; 10] {
    let mut n = [0.0; 10];
    for i in 0..4 {
        n[i] = l[i] * (2.0 * l[i] - 1.0);
    }
    for (e, [i, j]) in TET10_EDGES.iter().enumerate() {
        n[4 + e] = 4.0 * l[*i] * l[*j];
    }
    n
}

/// Rest data of one quadratic tet: per quadrature point its weight (the volume it stands for)
/// and the shape functions' rest gradients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tet10Rest {
    /// Weight `w_q = det J / 24` \[m^3\] of each point (they sum to the rest volume).
    pub weights: [f64; 4],
    /// `grad N_a` \[1/m\] at each point `(4 x 10)`.
    pub grads: [[Vec3; 10]; 4],
}

impl Tet10Rest {
    /// Rest data from the ten rest positions \[m\] (vertices, then edge nodes); `None` when the
    /// map is degenerate or inverted at a quadrature point (`det J <= 0`).
    pub fn new(x: &[Vec3; 10]) -> Option<Tet10Rest> {
        let mut weights = [0.0; 4];
        let mut grads = [[Vec3::zeros(); 10]; 4];
        for (q, l) in points().into_iter().enumerate() {
            let d = shape_derivatives(l);
            // Independent coordinates (L1, L2, L3), L0 = 1 - their sum.
            let dxi: [Vec3; 10] = std::array::from_fn(|a| Vec3::new(d[a][1] - d[a][0], d[a][2] - d[a][0], d[a][3] - d[a][0]));
            let j: Mat3 = (0..10).map(|a| x[a] * dxi[a].transpose()).sum();
            let det = j.determinant();
            if !(det > 0.0 && det.is_finite()) {
                return None;
            }
            let jit = j.try_inverse()?.transpose();
            weights[q] = det / 24.0;
            grads[q] = std::array::from_fn(|a| jit * dxi[a]);
        }
        Some(Tet10Rest { weights, grads })
    }

    /// The straight-sided element on four vertices \[m\]: its edge nodes at the midpoints.
    pub fn straight(v: &[Vec3; 4]) -> Option<Tet10Rest> {
        Tet10Rest::new(&with_midpoints(v))
    }

    /// Rest volume \[m^3\].
    pub fn volume(&self) -> f64 {
        self.weights.iter().sum()
    }

    /// `sum_q w_q sum_a |g_qa|^2` \[m\]: with a modulus, the element's stiffness scale.
    pub fn gradient_scale(&self) -> f64 {
        self.weights.iter().zip(&self.grads).map(|(w, g)| w * g.iter().map(|v| v.norm_squared()).sum::<f64>()).sum()
    }
}

/// The ten nodes of the straight element on vertices `v`: the vertices, then the edge midpoints.
pub fn with_midpoints(v: &[Vec3; 4]) -> [Vec3; 10] {
    std::array::from_fn(|a| if a < 4 { v[a] } else { (v[TET10_EDGES[a - 4][0]] + v[TET10_EDGES[a - 4][1]]) * 0.5 })
}

/// `sum_a x_a g_a^T`: the deformation gradient of positions `x` (or its rate, of velocities).
#[inline]
pub fn gradient(x: &[Vec3; 10], g: &[Vec3; 10]) -> Mat3 {
    let mut f = Mat3::zeros();
    for a in 0..10 {
        f += x[a] * g[a].transpose();
    }
    f
}

/// Adds `-w P g_a` to `out[a]`.
#[inline]
fn add_nodal(p: &Mat3, w: f64, g: &[Vec3; 10], out: &mut [Vec3; 10]) {
    let pw = -w * p;
    for a in 0..10 {
        out[a] += pw * g[a];
    }
}

/// Elastic energy density `psi` \[J/m^3\] and first Piola stress `P` \[Pa\] at `F`.
#[inline]
fn energy_piola(m: &Material, f: &Mat3) -> (f64, Mat3) {
    match m.law() {
        Law::StVenantKirchhoff => {
            let e = material::green_strain(f);
            (material::energy_density(m, &e), f * material::stress(m, &e))
        }
        Law::NeoHookean => {
            let (w, p, _) = neo_hookean::energy_piola(m, f);
            (w, p)
        }
    }
}

/// Strain energy of the element \[J\] at positions `x` \[m\].
pub fn strain_energy(x: &[Vec3; 10], rest: &Tet10Rest, m: &Material) -> f64 {
    (0..4)
        .map(|q| {
            let f = gradient(x, &rest.grads[q]);
            let psi = match m.law() {
                Law::StVenantKirchhoff => material::energy_density(m, &material::green_strain(&f)),
                Law::NeoHookean => neo_hookean::energy_density(m, &f),
            };
            rest.weights[q] * psi
        })
        .sum()
}

/// Elastic energy \[J\], elastic nodal forces \[N\] and the least `det F` over the points.
pub fn elastic_energy_forces(x: &[Vec3; 10], rest: &Tet10Rest, m: &Material) -> (f64, [Vec3; 10], f64) {
    let mut out = [Vec3::zeros(); 10];
    let (mut w, mut det) = (0.0, f64::INFINITY);
    for q in 0..4 {
        let f = gradient(x, &rest.grads[q]);
        let (psi, p) = energy_piola(m, &f);
        w += rest.weights[q] * psi;
        det = det.min(f.determinant());
        add_nodal(&p, rest.weights[q], &rest.grads[q], &mut out);
    }
    (w, out, det)
}

/// Nodal forces \[N\] of positions `x` \[m\] and, with `v` \[m/s\], the viscous stress of eq. (11).
pub fn forces(x: &[Vec3; 10], v: Option<&[Vec3; 10]>, rest: &Tet10Rest, m: &Material) -> [Vec3; 10] {
    let mut out = [Vec3::zeros(); 10];
    for q in 0..4 {
        let g = &rest.grads[q];
        let f = gradient(x, g);
        let mut p = energy_piola(m, &f).1;
        if let Some(v) = v {
            let f_dot = gradient(v, g);
            p += f * material::viscous_stress(m, &material::strain_rate(&f, &f_dot));
        }
        add_nodal(&p, rest.weights[q], g, &mut out);
    }
    out
}

/// Elastic first Piola stress \[Pa\] and energy density \[J/m^3\], averaged over the points with
/// their weights (for output: one value per element).
pub fn mean_stress(x: &[Vec3; 10], rest: &Tet10Rest, m: &Material) -> (Mat3, f64, Mat3) {
    let (mut p, mut psi, mut f) = (Mat3::zeros(), 0.0, Mat3::zeros());
    let vol = rest.volume();
    for q in 0..4 {
        let fq = gradient(x, &rest.grads[q]);
        let (e, pq) = energy_piola(m, &fq);
        let w = rest.weights[q] / vol;
        p += w * pq;
        psi += w * e;
        f += w * fq;
    }
    (p, psi, f)
}

/// Blocks `(10 x 10)` of 3x3 matrices.
pub type Blocks = [[Mat3; 10]; 10];

/// The Neo-Hookean tangent blocks at one point, times `c` (`-w`: a force Jacobian), with
/// `definite` the positive semi-definite approximation of `fem/tangent.rs` (the cofactor term
/// dropped, `h''` clamped at 0).
fn neo_hookean_blocks(f: &Mat3, g: &[Vec3; 10], m: &Material, c: f64, definite: bool, out: &mut Blocks) {
    let (lam, mu) = (m.lambda(), m.mu());
    let cof = neo_hookean::cofactor(f);
    let j = f.column(0).dot(&cof.column(0));
    let (_, h1, mut h2) = neo_hookean::volumetric(lam, mu, j);
    if definite {
        h2 = h2.max(0.0);
    }
    let cg: [Vec3; 10] = std::array::from_fn(|a| cof * g[a]);
    for a in 0..10 {
        for b in 0..10 {
            let mut blk = Mat3::from_diagonal_element(mu * g[a].dot(&g[b])) + h2 * cg[a] * cg[b].transpose();
            if !definite {
                blk += h1 * neo_hookean::cross_matrix(&(f * g[b].cross(&g[a])));
            }
            out[a][b] += c * blk;
        }
    }
}

fn add_blocks(out: &mut Blocks, add: &Blocks) {
    for a in 0..10 {
        for b in 0..10 {
            out[a][b] += add[a][b];
        }
    }
}

/// Force Jacobian blocks `K_ab = d f_a / d x_b` of the elastic force at positions `x`, and, if
/// the material is damped, `D_ab = d f_a / d v_b` of the viscous force: the linear tet's
/// ([`super::tet4::jacobians`]) summed over the points.
pub fn jacobians(x: &[Vec3; 10], rest: &Tet10Rest, m: &Material) -> (Box<Blocks>, Option<Box<Blocks>>) {
    let mut k = Box::new([[Mat3::zeros(); 10]; 10]);
    let mut d = (!m.is_undamped()).then(|| Box::new([[Mat3::zeros(); 10]; 10]));
    for q in 0..4 {
        let (g, w) = (&rest.grads[q], rest.weights[q]);
        let f = gradient(x, g);
        match m.law() {
            Law::StVenantKirchhoff => {
                let s = material::stress(m, &material::green_strain(&f));
                add_blocks(&mut k, &svk_blocks(&f, &s, m.lambda(), m.mu(), g, -w));
            }
            Law::NeoHookean => neo_hookean_blocks(&f, g, m, -w, false, &mut k),
        }
        if let Some(d) = d.as_mut() {
            let dmp = m.damping();
            add_blocks(d, &svk_blocks(&f, &Mat3::zeros(), dmp.phi, dmp.psi, g, -w));
        }
    }
    (k, d)
}

/// Negative semi-definite approximation of `d f / d x` at positions `x` (`fem/tangent.rs`'s, at
/// every point).
pub fn definite_jacobian(x: &[Vec3; 10], rest: &Tet10Rest, m: &Material) -> Box<Blocks> {
    let mut k = Box::new([[Mat3::zeros(); 10]; 10]);
    for q in 0..4 {
        let (g, w) = (&rest.grads[q], rest.weights[q]);
        let f = gradient(x, g);
        match m.law() {
            Law::StVenantKirchhoff => {
                let s_pos = super::tangent::positive_part(&material::stress(m, &material::green_strain(&f)));
                add_blocks(&mut k, &svk_blocks(&f, &s_pos, m.lambda(), m.mu(), g, -w));
            }
            Law::NeoHookean => neo_hookean_blocks(&f, g, m, -w, true, &mut k),
        }
    }
    k
}

/// The viscous dissipation potential of one step (`fem/viscous.rs`) summed over the points:
/// `D` \[J\] from `x_n` to `x` over `h` \[s\], and the forces `-dD/dx` \[N\].
pub fn step_dissipation(x: &[Vec3; 10], x_n: &[Vec3; 10], rest: &Tet10Rest, m: &Material, h: f64) -> (f64, [Vec3; 10]) {
    let d = m.damping();
    let mut out = [Vec3::zeros(); 10];
    let mut energy = 0.0;
    for q in 0..4 {
        let (g, w) = (&rest.grads[q], rest.weights[q]);
        let f = gradient(x, g);
        let de = material::green_strain(&f) - material::green_strain(&gradient(x_n, g));
        let tr = de.trace();
        energy += w / h * (0.5 * d.phi * tr * tr + d.psi * de.norm_squared());
        let s = (Mat3::from_diagonal_element(d.phi * tr) + 2.0 * d.psi * de) / h;
        add_nodal(&(f * s), w, g, &mut out);
    }
    (energy, out)
}

/// Hessian blocks `d^2 D / dx_a dx_b` of [`step_dissipation`] (positive at rest): the
/// St. Venant-Kirchhoff form with `(phi, psi) / h` for Lame's constants, at every point.
pub fn step_dissipation_hessian(x: &[Vec3; 10], x_n: &[Vec3; 10], rest: &Tet10Rest, m: &Material, h: f64) -> Box<Blocks> {
    let d = m.damping();
    let mut out = Box::new([[Mat3::zeros(); 10]; 10]);
    for q in 0..4 {
        let (g, w) = (&rest.grads[q], rest.weights[q]);
        let f = gradient(x, g);
        let de = material::green_strain(&f) - material::green_strain(&gradient(x_n, g));
        let s = (Mat3::from_diagonal_element(d.phi * de.trace()) + 2.0 * d.psi * de) / h;
        add_blocks(&mut out, &svk_blocks(&f, &s, d.phi / h, d.psi / h, g, w));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};

    fn mat(law: Law, damped: bool) -> Material {
        let d = if damped { Damping { phi: 3.0, psi: 7.0 } } else { Damping::NONE };
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, d).unwrap().with_law(law)
    }

    /// A curved element: the straight one with its edge nodes moved off the midpoints.
    fn rest_nodes() -> [Vec3; 10] {
        let v = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ];
        let mut x = with_midpoints(&v);
        x[4] += Vec3::new(0.0, -4e-4, 3e-4);
        x[9] += Vec3::new(2e-4, 1e-4, 0.0);
        x
    }

    fn deformed(u: &[Vec3; 10]) -> [Vec3; 10] {
        let a = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        std::array::from_fn(|i| a * u[i] + Vec3::new(1e-4 * (i as f64 % 3.0), -2e-4 * ((i * 7) % 5) as f64 / 5.0, 3e-4 * ((i * 3) % 4) as f64 / 4.0))
    }

    #[test]
    fn interpolates_and_integrates_the_volume() {
        let v = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.011, 0.001, -0.002),
            Vec3::new(0.002, 0.009, 0.001),
            Vec3::new(-0.001, 0.002, 0.012),
        ];
        let r = Tet10Rest::straight(&v).unwrap();
        let vol = crate::mesh::signed_volume(&v[0], &v[1], &v[2], &v[3]);
        assert!((r.volume() - vol).abs() < 1e-15 * vol.abs().max(1e-30) + 1e-22);
        // The gradients reproduce an affine field exactly: F of x = A X + b is A at every point.
        let a = Mat3::new(1.1, 0.05, -0.03, 0.02, 0.93, 0.08, -0.04, 0.06, 1.07);
        let x0 = rest_nodes();
        let rc = Tet10Rest::new(&x0).unwrap();
        let x: [Vec3; 10] = std::array::from_fn(|i| a * x0[i] + Vec3::new(0.3, -0.2, 0.1));
        for q in 0..4 {
            assert!((gradient(&x, &rc.grads[q]) - a).norm() < 1e-10);
            // The gradients of functions that sum to one sum to zero.
            assert!(rc.grads[q].iter().sum::<Vec3>().norm() < 1e-9);
        }
        let n = shape_values([0.1, 0.2, 0.3, 0.4]);
        assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        assert!((VERTEX_MASS * 4.0 + EDGE_MASS * 6.0 - 1.0).abs() < 1e-15);
        // An inverted element is refused.
        let mirrored: [Vec3; 10] = std::array::from_fn(|i| Vec3::new(-x0[i].x, x0[i].y, x0[i].z));
        assert!(Tet10Rest::new(&mirrored).is_none());
        // So is an edge node pulled so far off its edge that the map folds.
        let mut folded = x0;
        folded[4] = x0[2] * 1.5;
        assert!(Tet10Rest::new(&folded).is_none());
    }

    #[test]
    fn forces_are_minus_the_energy_gradient_and_sum_to_zero() {
        let x0 = rest_nodes();
        let r = Tet10Rest::new(&x0).unwrap();
        let x = deformed(&x0);
        for law in [Law::StVenantKirchhoff, Law::NeoHookean] {
            let m = mat(law, false);
            let f = forces(&x, None, &r, &m);
            let (w, f2, _) = elastic_energy_forces(&x, &r, &m);
            assert!((w - strain_energy(&x, &r, &m)).abs() <= 1e-12 * w.abs());
            let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
            assert!(f.iter().sum::<Vec3>().norm() < 1e-10 * scale);
            let h = 1e-9;
            for a in 0..10 {
                assert!((f[a] - f2[a]).norm() <= 1e-12 * scale);
                for c in 0..3 {
                    let (mut xp, mut xm) = (x, x);
                    xp[a][c] += h;
                    xm[a][c] -= h;
                    let fd = -(strain_energy(&xp, &r, &m) - strain_energy(&xm, &r, &m)) / (2.0 * h);
                    assert!((fd - f[a][c]).abs() <= 1e-6 * scale, "{law:?} node {a} comp {c}: fd {fd} vs {}", f[a][c]);
                }
            }
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let x0 = rest_nodes();
        let r = Tet10Rest::new(&x0).unwrap();
        let x = deformed(&x0);
        let v: [Vec3; 10] = std::array::from_fn(|i| Vec3::new(0.01 * i as f64, -0.02, 0.005 * (i % 3) as f64));
        for law in [Law::StVenantKirchhoff, Law::NeoHookean] {
            let m = mat(law, true);
            let (k, d) = jacobians(&x, &r, &m);
            let d = d.unwrap();
            let h = 1e-8;
            let mut worst: f64 = 0.0;
            let scale = k.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
            for b in 0..10 {
                for c in 0..3 {
                    let (mut xp, mut xm) = (x, x);
                    xp[b][c] += h;
                    xm[b][c] -= h;
                    let (fp, fm) = (forces(&xp, None, &r, &m), forces(&xm, None, &r, &m));
                    let (mut vp, mut vm) = (v, v);
                    vp[b][c] += h;
                    vm[b][c] -= h;
                    let gp = forces(&x, Some(&vp), &r, &m);
                    let gm = forces(&x, Some(&vm), &r, &m);
                    for a in 0..10 {
                        let fd = (fp[a] - fm[a]) / (2.0 * h);
                        worst = worst.max((fd - k[a][b].column(c)).norm() / scale);
                        let fdv = (gp[a] - gm[a]) / (2.0 * h);
                        let dscale = d.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
                        assert!((fdv - d[a][b].column(c)).norm() <= 1e-6 * dscale, "{law:?} D[{a}][{b}] col {c}");
                    }
                }
            }
            assert!(worst < 1e-6, "{law:?}: K vs finite differences {worst:e}");
        }
    }

    #[test]
    fn rigid_motion_costs_nothing_and_dissipation_is_its_gradient() {
        let x0 = rest_nodes();
        let r = Tet10Rest::new(&x0).unwrap();
        let rot = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vec3::new(0.3, -0.5, 0.8)), 2.1).into_inner();
        let x: [Vec3; 10] = std::array::from_fn(|i| rot * x0[i] + Vec3::new(0.1, 0.2, -0.3));
        let m = mat(Law::StVenantKirchhoff, true);
        let f_scale = forces(&deformed(&x0), None, &r, &m).iter().map(|v| v.norm()).fold(0.0, f64::max);
        assert!(forces(&x, None, &r, &m).iter().all(|f| f.norm() < 1e-9 * f_scale));
        assert!(strain_energy(&x, &r, &m).abs() < 1e-18);
        // The step's dissipation: zero over a rigid step, its force minus its gradient.
        assert!(step_dissipation(&x, &x0, &r, &m, 1e-3).0.abs() < 1e-15);
        let xd = deformed(&x0);
        let (_, fv) = step_dissipation(&xd, &x0, &r, &m, 1e-3);
        let h = 1e-9;
        let scale = fv.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for a in 0..10 {
            for c in 0..3 {
                let (mut xp, mut xm) = (xd, xd);
                xp[a][c] += h;
                xm[a][c] -= h;
                let fd = -(step_dissipation(&xp, &x0, &r, &m, 1e-3).0 - step_dissipation(&xm, &x0, &r, &m, 1e-3).0) / (2.0 * h);
                assert!((fd - fv[a][c]).abs() <= 1e-6 * scale);
            }
        }
    }

    #[test]
    fn dissipation_hessian_matches_finite_differences() {
        let x0 = rest_nodes();
        let r = Tet10Rest::new(&x0).unwrap();
        let x = deformed(&x0);
        let m = mat(Law::StVenantKirchhoff, true);
        let hs = step_dissipation_hessian(&x, &x0, &r, &m, 1e-3);
        let scale = hs.iter().flatten().map(|b| b.norm()).fold(0.0, f64::max);
        let h = 1e-9;
        for b in 0..10 {
            for c in 0..3 {
                let (mut xp, mut xm) = (x, x);
                xp[b][c] += h;
                xm[b][c] -= h;
                let (fp, fm) = (step_dissipation(&xp, &x0, &r, &m, 1e-3).1, step_dissipation(&xm, &x0, &r, &m, 1e-3).1);
                for a in 0..10 {
                    // The forces are minus the gradient: their derivative is minus the Hessian.
                    let fd = -(fp[a] - fm[a]) / (2.0 * h);
                    assert!((fd - hs[a][b].column(c)).norm() <= 1e-6 * scale, "[{a}][{b}] col {c}");
                }
            }
        }
    }

    /// At rest the definite approximation is the exact stiffness (St. Venant-Kirchhoff), and it
    /// stays negative semi-definite under compression, where the exact tangent is not.
    #[test]
    fn definite_tangent() {
        use nalgebra::DMatrix;
        let x0 = rest_nodes();
        let r = Tet10Rest::new(&x0).unwrap();
        let dense = |k: &Blocks| DMatrix::from_fn(30, 30, |i, j| k[i / 3][j / 3][(i % 3, j % 3)]);
        for law in [Law::StVenantKirchhoff, Law::NeoHookean] {
            let m = mat(law, false);
            if law == Law::StVenantKirchhoff {
                let (exact, approx) = (dense(&jacobians(&x0, &r, &m).0), dense(&definite_jacobian(&x0, &r, &m)));
                assert!((&exact - &approx).norm() <= 1e-9 * approx.norm());
            }
            let a = Mat3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.0, 0.0, 0.4);
            let x: [Vec3; 10] = std::array::from_fn(|i| a * x0[i]);
            let k = dense(&definite_jacobian(&x, &r, &m));
            let sym = (&k + k.transpose()) * 0.5;
            let top = sym.symmetric_eigenvalues().max();
            assert!(top <= 1e-9 * k.norm(), "{law:?}: largest eigenvalue {top:e}");
        }
    }
}
