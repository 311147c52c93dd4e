//! Conservation and dissipation properties of the three time integrators.
//!
//! (a) Free body: total linear momentum is conserved (internal forces sum to zero per element;
//!     for backward Euler `1^T K = 1^T D = 0`, so the linear solve preserves `sum m v`).
//! (b) Damped, clamped, unloaded: total energy (kinetic + strain) never increases.
//! (c) Undamped: energy never exceeds its initial value (backward Euler is dissipative).
//! (d) Gravity: backward Euler settles onto the static equilibrium under gravity.
//! (e) The stable semi-implicit filter: spectral radius of the linearised step <= 1 at 1, 10 and
//!     100 ms on the wall where the paper's filter is unstable, and its factor equals
//!     lambda_max(blockdiag(K)^-1 K) / 2 from a dense eigen solve, within the 2% margin.
//!
//! What a wrong implementation would do: a force assembly that is not translation invariant, a
//! Jacobian whose rows do not sum to zero, or a solver that treats some node inconsistently
//! drifts the momentum; a sign error in the damping, or a viscous Jacobian of the wrong sign,
//! pumps energy in; an integrator with an explicit (forward) treatment of the stiffness grows
//! energy at dt = 1 ms on these meshes (the explicit limit is ~1e-4 s); a BE step that does not
//! converge to the nonlinear equilibrium settles elsewhere than `static_solve`; a filter factor
//! below lambda_max / 2 (power iteration stopped early) leaves a spectral radius above 1 at large dt.
//!
//! The paper's semi-implicit scheme fails (a) by construction and is linearly unstable at 1 ms on
//! the 1320-tet wall and with strong damping: the `known_issue_*` and
//! `semi_implicit_filter_does_not_conserve_momentum` tests pin the measured behaviour, and
//! (b)/(c) run it on the coarse wall where it is stable. Numbers in VALIDATION.md.

#[path = "support/common.rs"]
mod common;

use common::*;
use palpate_core::divergence::speed_bound;
use palpate_core::integrate::Filter;
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::mesh::generate::{base_nodes, ellipsoid_wall, truncated_ellipsoid_wall, EllipsoidWall, TruncatedEllipsoidWall};
use palpate_core::{step, Integrator, Material, Model, ModelBuilder, State, StepError, Vec3, Workspace};

fn free_body(integ: Integrator, phi: f64, psi: f64) -> Model {
    let mesh = ellipsoid_wall(&EllipsoidWall::default());
    ModelBuilder::new(mesh, material(3.0e4, 0.4, 1000.0, phi, psi)).integrator(integ).build().unwrap()
}

fn wall(p: &TruncatedEllipsoidWall, mat: Material, integ: Integrator, g: Vec3) -> Model {
    let mesh = truncated_ellipsoid_wall(p);
    let fixed = base_nodes(&mesh, p.z_cut, 1e-9);
    ModelBuilder::new(mesh, mat).fixed_nodes(fixed).gravity(g).integrator(integ).build().unwrap()
}

fn energy(model: &Model, s: &State) -> f64 {
    model.kinetic_energy(&s.v) + model.strain_energy(&s.x)
}

/// A deformed initial state: the static equilibrium under a sideways load on the upper half of
/// the outer surface (strains of a few percent), released with zero velocity.
fn deformed_wall_state(model: &Model, total: f64) -> State {
    let pts = model.mesh().points();
    let zmax = pts.iter().map(|p| p.z).fold(f64::MIN, f64::max);
    let loaded: Vec<usize> = (0..model.n_nodes()).filter(|&i| pts[i].z > 0.5 * zmax && pts[i].x > 0.0).collect();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    for &i in &loaded {
        f[i] = Vec3::new(-total / loaded.len() as f64, 0.3 * total / loaded.len() as f64, 0.0);
    }
    let sol = static_solve(model, &f, &StaticOptions { load_steps: 4, ..StaticOptions::default() }).unwrap();
    let mut s = State::rest(model);
    s.x = sol.x;
    s
}

// ---------------------------------------------------------------------------------------------
// (a) momentum
// ---------------------------------------------------------------------------------------------

/// Runs 200 steps of a free, deformed, moving body and returns the worst per-step momentum change
/// relative to the initial momentum `|p0|`, and the total change after 200 steps. The mean drift
/// velocity (0.1 m/s) is comparable to the random part (+-0.05 m/s per component), so `|p0|` is of
/// the order of `sum m |v|`: round-off of the solves is ~1e-15 of it.
fn momentum_drift(integ: Integrator, phi: f64, psi: f64) -> (f64, f64) {
    let model = free_body(integ, phi, psi);
    let mut rng = Rng::new(21);
    let mut s = State::rest(&model);
    let v0 = Vec3::new(0.05, -0.02, 0.08);
    for i in 0..model.n_nodes() {
        s.x[i] += rng.vec3(3e-4); // ~10% of the element size: strains ~0.1
        s.v[i] = v0 + rng.vec3(0.05);
    }
    let mut ws = Workspace::new(&model);
    let p0 = model.momentum(&s.v);
    let mut p = p0;
    let mut worst: f64 = 0.0;
    for _ in 0..200 {
        step(&model, &mut s, &mut ws, 1e-3).unwrap();
        let pn = model.momentum(&s.v);
        worst = worst.max((pn - p).norm() / p0.norm());
        p = pn;
    }
    (worst, (p - p0).norm() / p0.norm())
}

#[test]
fn backward_euler_conserves_momentum_of_a_free_body() {
    for (name, integ) in &SCHEMES[1..4] {
        for (phi, psi) in [(0.0, 0.0), (5.0, 5.0)] {
            let (per_step, total) = momentum_drift(*integ, phi, psi);
            println!("{name} (phi {phi}, psi {psi}): worst per-step |dp|/|p| = {per_step:.2e}, after 200 steps {total:.2e}");
            assert!(per_step <= 1e-12, "{name}: momentum changes by {per_step:e} per step");
        }
    }
}

/// The paper's semi-implicit filter `v <- (I - dt^2/m J_ii)^-1 v~` scales each node's velocity by
/// its own matrix, so it does not preserve `sum m v`: in particular it slows a rigid translation,
/// which feels no force at all. This test pins the measured behaviour (see the report /
/// VALIDATION.md): the loss is large, and for a uniform translation at rest it is exactly what
/// eq. (34) prescribes, `p1 = sum_i m_i A_i^-1 v0`.
#[test]
fn semi_implicit_filter_does_not_conserve_momentum() {
    let (per_step, total) = momentum_drift(Integrator::semi_implicit(), 0.0, 0.0);
    println!("semi-implicit: worst per-step |dp|/|p| = {per_step:.2e}, after 200 steps |p - p0|/|p0| = {total:.2e}");
    assert!(per_step > 1e-3, "semi-implicit momentum drift {per_step:e}: smaller than measured; update the docs");

    // A rigid translation at rest: no force anywhere, yet the filter slows every node.
    let model = free_body(Integrator::semi_implicit(), 0.0, 0.0);
    let mut s = State::rest(&model);
    let v0 = Vec3::new(0.1, 0.0, 0.0);
    s.v.iter_mut().for_each(|v| *v = v0);
    let mut ws = Workspace::new(&model);
    let dt = 1e-3;
    step(&model, &mut s, &mut ws, dt).unwrap();
    let p_expect: Vec3 = (0..model.n_nodes())
        .map(|i| {
            let m = model.masses()[i];
            let a = palpate_core::Mat3::identity() - (dt * dt / m) * model.node_jacobians()[i];
            m * (a.try_inverse().unwrap() * v0)
        })
        .sum();
    let p1 = model.momentum(&s.v);
    let p0 = model.momentum(&vec![v0; model.n_nodes()]);
    println!("rigid translation, one step: |p1|/|p0| = {:.4} (eq. 34 predicts {:.4})", p1.norm() / p0.norm(), p_expect.norm() / p0.norm());
    assert!((p1 - p_expect).norm() <= 1e-12 * p0.norm(), "semi-implicit step differs from eq. (34)");
}

// ---------------------------------------------------------------------------------------------
// (b) damped energy decay, (c) undamped energy bound
// ---------------------------------------------------------------------------------------------

/// Energies after each of `steps` steps from `s`.
fn energies(model: &Model, mut s: State, steps: usize, dt: f64) -> Vec<f64> {
    let mut ws = Workspace::new(model);
    let mut e = vec![energy(model, &s)];
    for k in 0..steps {
        step(model, &mut s, &mut ws, dt).unwrap_or_else(|err| panic!("step {k}: {err}"));
        e.push(energy(model, &s));
    }
    e
}

/// The meshes each scheme is run on, with the number of undamped steps: the default truncated
/// wall (1320 tets) for backward Euler; the semi-implicit scheme is linearly unstable on it at
/// dt = 1 ms (see `known_issue_semi_implicit_unstable_on_default_truncated_wall`), so it runs on
/// the coarse `with_resolution(3)` wall (180 tets), where it is stable; BE runs there too.
/// All run 2000 undamped steps (Newton on the 1320-tet wall: 4-10 ms a step on the 2-core VM,
/// the longest part of this file).
fn cases() -> Vec<(String, TruncatedEllipsoidWall, Integrator, usize)> {
    let mut v = Vec::new();
    for (mname, p) in [("wall 1320 tets", TruncatedEllipsoidWall::default()), ("wall 180 tets", TruncatedEllipsoidWall::with_resolution(3))] {
        let fine = mname.starts_with("wall 1320");
        for (name, integ) in SCHEMES {
            if matches!(integ, Integrator::SemiImplicit { filter: Filter::Paper }) && fine {
                continue;
            }
            v.push((format!("{name}, {mname}"), p.clone(), integ, 2000));
        }
    }
    v
}

/// Damping phi = psi = 1 Pa s (relaxation time psi/mu ~ 0.1 ms). With 5 Pa s the semi-implicit
/// scheme is unstable at dt = 1 ms even on the coarse wall (see
/// `known_issue_semi_implicit_unstable_with_strong_damping`).
#[test]
fn damped_energy_decays_monotonically() {
    let mat = material(3.0e4, 0.4, 1000.0, 1.0, 1.0);
    for (name, p, integ, _) in cases() {
        let model = wall(&p, mat, integ, Vec3::zeros());
        let s = deformed_wall_state(&model, 0.5);
        let e = energies(&model, s, 300, 1e-3);
        let e0 = e[0];
        // Round-off allowance: the strain energy of a tiny residual deformation is computed from
        // F with an absolute error ~1e-15, i.e. a relative error that grows as the energy decays;
        // 1e-12 E0 absolute covers it.
        let worst_rise = e.windows(2).map(|w| w[1] - w[0]).fold(f64::MIN, f64::max);
        println!("{name}: E0 = {e0:.4e} J, E(100) = {:.3e}, E(300) = {:.3e}, worst per-step rise {:.2e} E0", e[100], e[300], worst_rise / e0);
        assert!(worst_rise <= 1e-12 * e0, "{name}: energy rose by {:e} E0 in one step", worst_rise / e0);
        // The stable filter slows the motion itself (velocities scaled by the heavier filter), so
        // the rate-dependent viscous stress dissipates less per step: it creeps toward rest.
        if !name.contains("stable filter") {
            assert!(e[300] < 0.5 * e0, "{name}: damping dissipated too little ({:e} of E0 left)", e[300] / e0);
        }
    }
}

#[test]
fn undamped_energy_does_not_grow() {
    let mat = material(3.0e4, 0.4, 1000.0, 0.0, 0.0);
    for (name, p, integ, steps) in cases() {
        let model = wall(&p, mat, integ, Vec3::zeros());
        let s = deformed_wall_state(&model, 0.5);
        let t0 = std::time::Instant::now();
        let e = energies(&model, s, steps, 1e-3);
        let e0 = e[0];
        let max_ratio = e.iter().map(|v| v / e0).fold(f64::MIN, f64::max);
        let worst_rise = e.windows(2).map(|w| (w[1] - w[0]) / e0).fold(f64::MIN, f64::max);
        println!(
            "{name}: E0 = {e0:.4e} J, max E/E0 = {max_ratio:.12}, worst per-step rise {worst_rise:.2e} E0, E({steps})/E0 = {:.3e} ({:.1} s)",
            e[steps] / e0,
            t0.elapsed().as_secs_f64()
        );
        assert!(max_ratio <= 1.0 + 1e-9, "{name}: energy exceeded E0 by {:e}", max_ratio - 1.0);
    }
}

// ---------------------------------------------------------------------------------------------
// (d) gravity
// ---------------------------------------------------------------------------------------------

#[test]
fn backward_euler_settles_to_the_static_solution_under_gravity() {
    let p = TruncatedEllipsoidWall::default();
    let mat = material(3.0e4, 0.4, 1000.0, 0.0, 0.0);
    let g = Vec3::new(0.0, -9.81, 0.0); // sideways: bends the wall
    let reference = wall(&p, mat, Integrator::BackwardEulerLinear, g);
    let stat = static_solve(&reference, &vec![Vec3::zeros(); reference.n_nodes()], &StaticOptions::default()).unwrap();
    let u_stat: Vec<Vec3> = stat.x.iter().zip(reference.mesh().points()).map(|(x, x0)| x - x0).collect();
    let den = u_stat.iter().map(|u| u.norm_squared()).sum::<f64>().sqrt();
    for (name, integ) in &SCHEMES[1..4] {
        let model = wall(&p, mat, *integ, g);
        let mut s = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let dt = 1e-2;
        let mut k = 0;
        let rel = loop {
            step(&model, &mut s, &mut ws, dt).unwrap();
            k += 1;
            let num = s.x.iter().zip(&stat.x).map(|(a, b)| (a - b).norm_squared()).sum::<f64>().sqrt();
            if num / den <= 1e-7 || k >= 2000 {
                break num / den;
            }
        };
        println!("{name}: after {k} steps of {dt} s, rel L2 vs static = {rel:.2e} (max|u_static| = {:.3e} m)", max_norm(&u_stat));
        assert!(rel <= 1e-6, "{name}: settled {rel:e} away from static_solve");
    }
}

// ---------------------------------------------------------------------------------------------
// Known issues of the paper's semi-implicit scheme (characterisation tests: they pin measured
// behaviour so that the documentation stays true; if a change makes them fail because the
// scheme became stable, update VALIDATION.md and turn them into the strict tests above).
// ---------------------------------------------------------------------------------------------

fn perturbed_rest(model: &Model, amplitude: f64) -> State {
    let mut rng = Rng::new(1);
    let mut s = State::rest(model);
    for i in 0..model.n_nodes() {
        if !model.fixed()[i] {
            s.x[i] += rng.vec3(amplitude);
        }
    }
    s
}

/// Runs up to `steps` steps; returns `Err(step index)` at the first step error, else the final
/// energy ratio E/E0.
fn run_ratio(model: &Model, mut s: State, steps: usize, dt: f64) -> Result<f64, usize> {
    let e0 = energy(model, &s);
    let mut ws = Workspace::new(model);
    for k in 0..steps {
        if step(model, &mut s, &mut ws, dt).is_err() {
            return Err(k);
        }
    }
    Ok(energy(model, &s) / e0)
}

/// The per-node filter of eq. (34) is a block-Jacobi splitting of the implicit system: it is
/// stable for large dt only if the node blocks dominate the coupling (roughly, the largest
/// eigenvalue of `blockdiag(K)^-1 K` is <= 2; it is 2.55 on this mesh). Measured spectral radius
/// of the linearised semi-implicit step on `TruncatedEllipsoidWall::default()` (E = 30 kPa,
/// nu = 0.4, rho = 1000, base fixed, undamped): 0.99913 at dt = 0.4 and 0.5 ms, 1.150 at 0.7 ms,
/// 1.320 at 1 ms, 1.48 at 2 ms, 1.55 at 10 ms. A 1e-9 m random perturbation became non-finite
/// at step 71 of 1 ms; it is now reported as diverging (the speed bound) a few steps earlier
/// (`a_slow_divergence_is_reported_when_it_starts_before_anything_is_non_finite`). (The protocol meshes lv_190 / lv_1350 are stable at 1 ms: 0.99299 and
/// 0.99806.)
#[test]
fn known_issue_semi_implicit_unstable_on_default_truncated_wall() {
    let p = TruncatedEllipsoidWall::default();
    let model = wall(&p, material(3.0e4, 0.4, 1000.0, 0.0, 0.0), Integrator::semi_implicit(), Vec3::zeros());
    let blown = run_ratio(&model, perturbed_rest(&model, 1e-9), 300, 1e-3);
    let small_dt = run_ratio(&model, perturbed_rest(&model, 1e-9), 500, 4e-4);
    println!("semi-implicit, default wall: dt 1 ms -> {blown:?} (Err = step of blow-up); dt 0.4 ms -> E/E0 after 500 steps {small_dt:?}");
    assert!(blown.is_err(), "semi-implicit is now stable at 1 ms on the default wall: update the docs ({blown:?})");
    assert!(matches!(small_dt, Ok(r) if r < 1.0), "semi-implicit at 0.4 ms: {small_dt:?}");
}

/// Free degrees of freedom (3 per free node, node order) of `model`.
fn free_dofs(model: &Model) -> Vec<usize> {
    (0..model.n_nodes()).filter(|&i| !model.fixed()[i]).flat_map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect()
}

/// `-K` at rest on the free dofs (symmetric positive semi-definite), dense.
fn rest_stiffness(model: &Model) -> nalgebra::DMatrix<f64> {
    let k = dense_jacobian(model, model.mesh().points());
    let dofs = free_dofs(model);
    -k.select_rows(&dofs).select_columns(&dofs)
}

/// Spectral radius of the linearised undamped semi-implicit step of eq. (34) with filter factor
/// `alpha` at `dt`, by a dense eigenvalue solve, computed from the rest Jacobian alone (not from
/// the crate's filter blocks): with `u` the free displacements, `K = df/dx` at rest and
/// `F = blockdiag((I - alpha dt^2/m_i K_ii)^-1)`,
/// `v+ = F (v + dt M^-1 K u)`, `u+ = u + dt v+`, i.e. `(u, v) -> G (u, v)` with
/// `G = [[I + dt^2 F M^-1 K, dt F], [dt F M^-1 K, F]]`. (About 20 s for the 1320-tet wall: a
/// 1818 x 1818 real Schur decomposition.)
fn semi_implicit_spectral_radius(model: &Model, alpha: f64, dt: f64) -> f64 {
    let kp = rest_stiffness(model); // -K
    let nodes: Vec<usize> = (0..model.n_nodes()).filter(|&i| !model.fixed()[i]).collect();
    let n = kp.nrows();
    // F M^-1 K, block row by block row.
    let mut fmk = nalgebra::DMatrix::<f64>::zeros(n, n);
    let mut f = nalgebra::DMatrix::<f64>::zeros(n, n);
    for (a, &node) in nodes.iter().enumerate() {
        let m = model.masses()[node];
        let kaa = kp.fixed_view::<3, 3>(3 * a, 3 * a).into_owned();
        let fa = (palpate_core::Mat3::identity() + (alpha * dt * dt / m) * kaa).try_inverse().unwrap();
        f.fixed_view_mut::<3, 3>(3 * a, 3 * a).copy_from(&fa);
        let rows = -(fa / m) * kp.rows(3 * a, 3);
        fmk.rows_mut(3 * a, 3).copy_from(&rows);
    }
    let mut g = nalgebra::DMatrix::<f64>::zeros(2 * n, 2 * n);
    g.view_mut((0, 0), (n, n)).copy_from(&(nalgebra::DMatrix::<f64>::identity(n, n) + (dt * dt) * &fmk));
    g.view_mut((0, n), (n, n)).copy_from(&(dt * &f));
    g.view_mut((n, 0), (n, n)).copy_from(&(dt * &fmk));
    g.view_mut((n, n), (n, n)).copy_from(&f);
    g.complex_eigenvalues().iter().map(|c| c.norm()).fold(0.0, f64::max)
}

/// `lambda_max(blockdiag(K)^-1 K)` of the rest stiffness on the free dofs, by a dense symmetric
/// eigen solve of `D^-1/2 K D^-1/2` (`D` the 3x3 diagonal blocks).
fn block_jacobi_lambda_max(model: &Model) -> f64 {
    let kp = rest_stiffness(model);
    let n = kp.nrows();
    let mut s_inv = nalgebra::DMatrix::<f64>::zeros(n, n);
    for a in 0..n / 3 {
        let e = kp.fixed_view::<3, 3>(3 * a, 3 * a).into_owned().symmetric_eigen();
        assert!(e.eigenvalues.min() > 0.0, "diagonal block {a} not positive definite");
        let inv_sqrt = e.eigenvectors * palpate_core::Mat3::from_diagonal(&e.eigenvalues.map(|l| 1.0 / l.sqrt())) * e.eigenvectors.transpose();
        s_inv.fixed_view_mut::<3, 3>(3 * a, 3 * a).copy_from(&inv_sqrt);
    }
    let scaled = &s_inv * kp * &s_inv;
    let scaled = 0.5 * (&scaled + scaled.transpose());
    nalgebra::SymmetricEigen::new(scaled).eigenvalues.max()
}

/// The stable filter (`Filter::Stable`, `semi_implicit.rs`): with `alpha >= lambda_max(blockdiag(K)^-1
/// K) / 2` the linearised undamped scheme is stable at any dt. On the default truncated wall, where
/// the paper's filter has spectral radius 1.32 at 1 ms (test above), the spectral radius of the
/// linearised step must be <= 1 + 1e-9 at dt = 1, 10 and 100 ms; and `model.filter_factor()`,
/// estimated by power iteration with a 2% margin, must lie in `[lambda_max / 2, 1.02 lambda_max / 2]`
/// with `lambda_max` from a dense eigen solve here (below `lambda_max / 2` the scheme is unstable at
/// large dt: a power iteration stopped too early, or started in a subspace missing the top mode,
/// fails the lower bound; a wrong scaling (e.g. no `/ 2`, or the margin applied twice) the upper).
/// The helper is shown able to detect instability on the 180-tet wall, where the paper's filter
/// (alpha = 1 < lambda_max / 2) is unstable at 100 ms.
/// Measured: lambda_max = 2.54799 on the default wall, alpha = 1.29922 (1.0198 x lambda_max / 2);
/// spectral radius 0.99933 at 1, 10 and 100 ms (the slowest mode's `1 - lambda_min(K_d^-1 K) /
/// alpha` at large dt); 180-tet wall: lambda_max 2.436, at 100 ms the paper's filter gives 1.436,
/// the stable one 0.99676. (The exact stability bound of this linear scheme is `dt^2 K <= 4 M +
/// 2 alpha dt^2 K_d`, checked by bisection on alpha with this helper; `semi_implicit.rs` states
/// `2 (M + alpha dt^2 K_d)`, which is sufficient, not exact.) Runtime 34 s alone, ~72 s while the
/// file's other tests share the two cores (three dense 1818 x 1818 eigenvalue solves): this file
/// went from ~45 s to ~85 s.
#[test]
fn stable_filter_makes_the_semi_implicit_step_stable_on_default_truncated_wall() {
    let mat = material(3.0e4, 0.4, 1000.0, 0.0, 0.0);
    let stable = Integrator::SemiImplicit { filter: Filter::Stable };

    // The helper detects an unstable filter (cheap: 300 x 300).
    let coarse = wall(&TruncatedEllipsoidWall::with_resolution(3), mat, stable, Vec3::zeros());
    let l_coarse = block_jacobi_lambda_max(&coarse);
    let rho_paper = semi_implicit_spectral_radius(&coarse, 1.0, 0.1);
    let rho_coarse = semi_implicit_spectral_radius(&coarse, coarse.filter_factor(), 0.1);
    println!(
        "180-tet wall: lambda_max {l_coarse:.4}, dt 100 ms: paper filter rho = {rho_paper:.6}, stable filter (alpha {:.4}) rho = {rho_coarse:.9}",
        coarse.filter_factor()
    );
    assert!(l_coarse > 2.0 && rho_paper > 1.01, "the paper's filter is stable at 100 ms on the 180-tet wall (lambda_max {l_coarse}, rho {rho_paper})");
    assert!(rho_coarse <= 1.0 + 1e-9, "stable filter on the 180-tet wall: rho {rho_coarse}");

    let model = wall(&TruncatedEllipsoidWall::default(), mat, stable, Vec3::zeros());
    let alpha = model.filter_factor();
    let lmax = block_jacobi_lambda_max(&model);
    let ratio = alpha / (0.5 * lmax);
    println!("default wall: lambda_max(blockdiag(K)^-1 K) = {lmax:.5} (dense), filter_factor = {alpha:.5} = {ratio:.5} x lambda_max / 2");
    assert!((1.0..=1.02 * (1.0 + 1e-9)).contains(&ratio), "filter_factor {alpha} is {ratio} x lambda_max/2, outside [1, 1.02]");
    for dt in [1e-3, 1e-2, 1e-1] {
        let t0 = std::time::Instant::now();
        let rho = semi_implicit_spectral_radius(&model, alpha, dt);
        println!("default wall, stable filter, dt {:.0} ms: spectral radius {rho:.9} ({:.1} s)", dt * 1e3, t0.elapsed().as_secs_f64());
        assert!(rho <= 1.0 + 1e-9, "stable filter at dt {dt}: spectral radius {rho}");
    }
}

/// The viscous force's off-diagonal blocks are explicit in eq. (34) (palpate adds only the node's
/// own `D_ii` to the filter), so strong damping destabilises the scheme too. Measured on the
/// 180-tet wall at dt = 1 ms: spectral radius 0.9962 for phi = psi = 1 Pa s, 0.9964 for 2,
/// 1.006 for (phi, psi) = (0, 5), 1.127 for (5, 5); from a 1e-6 m perturbation E/E0 reaches
/// 1.1e5 with (5, 5). At dt = 0.3 ms (5, 5) is stable (0.9979).
#[test]
fn known_issue_semi_implicit_unstable_with_strong_damping() {
    let p = TruncatedEllipsoidWall::with_resolution(3);
    let model = wall(&p, material(3.0e4, 0.4, 1000.0, 5.0, 5.0), Integrator::semi_implicit(), Vec3::zeros());
    let big = run_ratio(&model, perturbed_rest(&model, 1e-6), 400, 1e-3);
    let small = run_ratio(&model, perturbed_rest(&model, 1e-6), 1000, 3e-4);
    println!("semi-implicit, 180-tet wall, phi = psi = 5 Pa s: dt 1 ms -> E/E0 {big:?}; dt 0.3 ms -> {small:?}");
    assert!(matches!(big, Ok(r) if r > 1.0) || big.is_err(), "semi-implicit with strong damping is now stable at 1 ms: update the docs ({big:?})");
    assert!(matches!(small, Ok(r) if r < 1.0), "semi-implicit with strong damping at 0.3 ms: {small:?}");
}

/// Largest speed \[m/s\] of a node relative to the body's mass-weighted mean velocity.
fn relative_speed(model: &Model, v: &[Vec3]) -> f64 {
    let m = model.masses();
    let mean = v.iter().zip(m).map(|(v, &m)| m * v).sum::<Vec3>() / m.iter().sum::<f64>();
    v.iter().map(|v| (v - mean).norm()).fold(0.0, f64::max)
}

/// Issue 15, item 4: a divergence is reported when it starts, not at overflow. The paper's
/// semi-implicit scheme on the default truncated wall at 1 ms grows its top mode by ~1.28 a step
/// (`known_issue_semi_implicit_unstable_on_default_truncated_wall`) from a 1e-9 m perturbation:
/// invisible (under a thousandth of the wave speed `c_p`) for 40 steps, past 0.1 `c_p` at step 61,
/// then, once its strain inverts tets, 80 `c_p` in one step; overflow came at step 71. The step
/// must fail with `StepError::Diverging` (not `NonFinite`), with every value finite, within 6
/// steps of the fastest node passing `c_p` (the strain-1 scale, where the motion stops being a
/// tissue's: `palpate_core::divergence`), and leave the state as it was. Without the speed
/// bound the run goes on to `NonFinite`: this test fails. Measured: reported at step 66, the
/// step that first passed `c_p` (0.88 `c_p` at step 65).
#[test]
fn a_slow_divergence_is_reported_when_it_starts_before_anything_is_non_finite() {
    let p = TruncatedEllipsoidWall::default();
    let model = wall(&p, material(3.0e4, 0.4, 1000.0, 0.0, 0.0), Integrator::semi_implicit(), Vec3::zeros());
    let c = model.material().wave_speed();
    let mut s = perturbed_rest(&model, 1e-9);
    let mut ws = Workspace::new(&model);
    let mut passed_c = None;
    for k in 0..300 {
        let before = s.clone();
        match step(&model, &mut s, &mut ws, 1e-3) {
            Ok(_) => {
                if relative_speed(&model, &s.v) > c {
                    passed_c.get_or_insert(k);
                }
            }
            Err(e) => {
                let StepError::Diverging { node, speed, bound, .. } = e else {
                    panic!("step {k}: {e} (expected Diverging)")
                };
                println!("step {k}: {e}; the last accepted step was at {:.2} c_p, first past c_p at {passed_c:?}", relative_speed(&model, &s.v) / c);
                assert!(node < model.n_nodes() && speed > bound && bound == speed_bound(model.material()));
                assert!(s.x == before.x && s.v == before.v && s.t == before.t, "the state was not restored");
                assert!(s.x.iter().chain(&s.v).all(|p| p.iter().all(|c| c.is_finite())));
                let first = passed_c.unwrap_or(k);
                assert!(k - first <= 6, "reported at step {k}, {} steps after passing c_p", k - first);
                return;
            }
        }
    }
    panic!("no divergence reported in 300 steps");
}
