//! Helpers shared by the integration tests: a small deterministic RNG (no dev-dependency needed),
//! materials, irregular meshes and dense-matrix utilities.
#![allow(dead_code)]

use palpate_core::fem::tet4;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::box_mesh;
use palpate_core::{Mat3, Material, Model, TetMesh, Vec3};

/// SplitMix64: deterministic, seedable, good enough for test data.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [-a, a).
    pub fn sym(&mut self, a: f64) -> f64 {
        a * (2.0 * self.unit() - 1.0)
    }
    /// Each component uniform in [-a, a).
    pub fn vec3(&mut self, a: f64) -> Vec3 {
        Vec3::new(self.sym(a), self.sym(a), self.sym(a))
    }
    /// Each entry uniform in [-a, a).
    pub fn mat3(&mut self, a: f64) -> Mat3 {
        Mat3::from_fn(|_, _| self.sym(a))
    }
}

pub fn material(young: f64, poisson: f64, density: f64, phi: f64, psi: f64) -> Material {
    Material::new(Elasticity::YoungPoisson { young, poisson }, density, Damping { phi, psi }).unwrap()
}

/// Rebuild a mesh from points and tets through the public validating constructor; panics if any
/// tet had to be reoriented (the perturbation inverted an element).
pub fn mesh_from(points: &[Vec3], tets: &[[usize; 4]]) -> TetMesh {
    let p: Vec<[f64; 3]> = points.iter().map(|v| [v.x, v.y, v.z]).collect();
    let t: Vec<[i64; 4]> = tets.iter().map(|t| t.map(|i| i as i64)).collect();
    let (m, w) = TetMesh::from_arrays(&p, &t).expect("valid mesh");
    assert!(w.is_empty(), "perturbation inverted tets: {w:?}");
    m
}

/// `box_mesh(size, cells)` with every node not on the box boundary moved by a random vector whose
/// components are uniform in `[-frac h_c, frac h_c]` (`h_c` the cell size along axis `c`).
pub fn perturbed_box(size: [f64; 3], cells: [usize; 3], frac: f64, seed: u64) -> TetMesh {
    let m = box_mesh(size, cells);
    let h = [size[0] / cells[0] as f64, size[1] / cells[1] as f64, size[2] / cells[2] as f64];
    let mut rng = Rng::new(seed);
    let pts: Vec<Vec3> = m
        .points()
        .iter()
        .map(|p| {
            let on_boundary = (0..3).any(|c| p[c] <= 1e-12 * size[c] || p[c] >= size[c] * (1.0 - 1e-12));
            if on_boundary {
                *p
            } else {
                p + Vec3::new(rng.sym(frac * h[0]), rng.sym(frac * h[1]), rng.sym(frac * h[2]))
            }
        })
        .collect();
    mesh_from(&pts, m.tets())
}

/// Nodes with `X[axis] == value` (to `tol`).
pub fn nodes_where(mesh: &TetMesh, axis: usize, value: f64, tol: f64) -> Vec<usize> {
    (0..mesh.n_nodes()).filter(|&i| (mesh.points()[i][axis] - value).abs() <= tol).collect()
}

/// Per node, `sum over boundary faces containing it of (outward area vector) / 3` in the rest
/// configuration. For a uniform first Piola stress `P` the nodal internal force is exactly
/// `-P * this` (divergence theorem on each linear tet: `V grad N_i = sum_{faces f of the tet
/// containing i} A_f n_f / 3`; interior faces cancel between neighbours).
pub fn boundary_area_vectors(mesh: &TetMesh) -> Vec<Vec3> {
    let p = mesh.points();
    let mut out = vec![Vec3::zeros(); mesh.n_nodes()];
    for f in mesh.boundary_faces() {
        let a = 0.5 * (p[f[1]] - p[f[0]]).cross(&(p[f[2]] - p[f[0]]));
        for &i in &f {
            out[i] += a / 3.0;
        }
    }
    out
}

/// Consistent nodal loads of a total force `total` spread as a uniform traction over the boundary
/// faces whose three nodes all satisfy `on_face`: node gets `total * (sum of its face areas / 3) / area`.
pub fn face_loads(mesh: &TetMesh, on_face: impl Fn(&Vec3) -> bool, total: Vec3) -> Vec<Vec3> {
    let p = mesh.points();
    let mut w = vec![0.0; mesh.n_nodes()];
    let mut area = 0.0;
    for f in mesh.boundary_faces() {
        if f.iter().all(|&i| on_face(&p[i])) {
            let a = 0.5 * (p[f[1]] - p[f[0]]).cross(&(p[f[2]] - p[f[0]])).norm();
            area += a;
            for &i in &f {
                w[i] += a / 3.0;
            }
        }
    }
    assert!(area > 0.0, "no boundary face selected");
    w.iter().map(|wi| total * (wi / area)).collect()
}

/// First Piola stress of one element recovered from its nodal forces: `P = -(1/V) sum_i f_i X_i^T`
/// (from `f_i = -V P grad N_i` and `sum_i X_i grad N_i^T = I`).
pub fn piola_from_forces(f: &[Vec3; 4], rest_x: &[Vec3; 4], volume: f64) -> Mat3 {
    // Use X_i - X_0 to avoid the cancellation of large absolute coordinates (sum_i f_i = 0).
    let mut s = Mat3::zeros();
    for i in 0..4 {
        s += f[i] * (rest_x[i] - rest_x[0]).transpose();
    }
    -s / volume
}

/// St Venant-Kirchhoff first Piola stress, computed independently of the crate's kernels.
pub fn svk_piola(f: &Mat3, lambda: f64, mu: f64) -> Mat3 {
    let e = 0.5 * (f.transpose() * f - Mat3::identity());
    f * (Mat3::identity() * (lambda * e.trace()) + 2.0 * mu * e)
}

/// Dense global elastic Jacobian `K = df/dx` (3n x 3n, all nodes, fixed or not) assembled from
/// `tet4::jacobians` at positions `x`.
pub fn dense_jacobian(model: &Model, x: &[Vec3]) -> nalgebra::DMatrix<f64> {
    let n = model.n_nodes();
    let mut k = nalgebra::DMatrix::<f64>::zeros(3 * n, 3 * n);
    for (t, r) in model.mesh().tets().iter().zip(model.rest()) {
        let (ke, _) = tet4::jacobians(&t.map(|i| x[i]), r, model.material());
        for a in 0..4 {
            for b in 0..4 {
                for p in 0..3 {
                    for q in 0..3 {
                        k[(3 * t[a] + p, 3 * t[b] + q)] += ke[a][b][(p, q)];
                    }
                }
            }
        }
    }
    k
}

/// Internal elastic forces \[N\] at `x` (a fresh vector).
pub fn forces(model: &Model, x: &[Vec3]) -> Vec<Vec3> {
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    model.internal_forces(x, None, &mut f);
    f
}

/// Dense central-difference Jacobian `df/dx` (3n x 3n) of the elastic force at `x`, step `h` \[m\].
pub fn fd_jacobian(model: &Model, x: &[Vec3], h: f64) -> nalgebra::DMatrix<f64> {
    let n = model.n_nodes();
    let mut k = nalgebra::DMatrix::zeros(3 * n, 3 * n);
    let mut xp = x.to_vec();
    for j in 0..n {
        for c in 0..3 {
            xp[j][c] = x[j][c] + h;
            let fp = forces(model, &xp);
            xp[j][c] = x[j][c] - h;
            let fm = forces(model, &xp);
            xp[j][c] = x[j][c];
            for i in 0..n {
                for r in 0..3 {
                    k[(3 * i + r, 3 * j + c)] = (fp[i][r] - fm[i][r]) / (2.0 * h);
                }
            }
        }
    }
    k
}

/// Largest `|f + dW/dx|` over the nodes and components, relative to `max |f|`, with `dW/dx` by
/// central differences of the total strain energy (step 1e-8 m) at `x`.
pub fn energy_gradient_error(model: &Model, x: &[Vec3]) -> f64 {
    let f = forces(model, x);
    let scale = max_norm(&f);
    let h = 1e-8;
    let mut xp = x.to_vec();
    let mut worst: f64 = 0.0;
    for i in 0..model.n_nodes() {
        for c in 0..3 {
            xp[i][c] = x[i][c] + h;
            let wp = model.strain_energy(&xp);
            xp[i][c] = x[i][c] - h;
            let wm = model.strain_energy(&xp);
            xp[i][c] = x[i][c];
            worst = worst.max((-(wp - wm) / (2.0 * h) - f[i][c]).abs() / scale);
        }
    }
    worst
}

pub fn max_norm(v: &[Vec3]) -> f64 {
    v.iter().map(|x| x.norm()).fold(0.0, f64::max)
}

/// Rotation matrix about a (non-zero) axis by `angle` \[rad\] (Rodrigues).
pub fn rotation(axis: Vec3, angle: f64) -> Mat3 {
    nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle).into_inner()
}

/// Every time-stepping scheme, labelled: the tests that must hold for all of them loop over this.
pub const SCHEMES: [(&str, palpate_core::Integrator); 5] = [
    ("semi-implicit", palpate_core::Integrator::semi_implicit()),
    ("BE linear", palpate_core::Integrator::BackwardEulerLinear),
    // Tight enough that its momentum error, `dt` times the sum of the final gradient, is round-off.
    ("BE Newton", palpate_core::Integrator::BackwardEulerNewton { max_iterations: 30, tolerance: 1e-12 }),
    ("BE quasi-Newton (default)", palpate_core::Integrator::quasi_newton()),
    ("semi-implicit, stable filter", palpate_core::Integrator::SemiImplicit { filter: palpate_core::integrate::Filter::Stable }),
];

/// A small wall clamped at its base, damped (the paper's 0.5, 0.5) and under gravity, so every
/// code path of the FEM step is exercised (tests/robustness.rs, tests/state_memory.rs).
pub fn clamped_wall(integ: palpate_core::Integrator) -> Model {
    use palpate_core::mesh::generate::{base_nodes, truncated_ellipsoid_wall, TruncatedEllipsoidWall};
    let p = TruncatedEllipsoidWall::with_resolution(3);
    let mesh = truncated_ellipsoid_wall(&p);
    let fixed = base_nodes(&mesh, p.z_cut, 1e-9);
    palpate_core::ModelBuilder::new(mesh, material(3.0e4, 0.4, 1000.0, 0.5, 0.5))
        .fixed_nodes(fixed)
        .gravity(Vec3::new(0.0, 0.0, -9.81))
        .integrator(integ)
        .build()
        .unwrap()
}
