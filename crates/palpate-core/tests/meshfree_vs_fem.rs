//! The particle solid against the FEM core on the same body, material and load (issue: meshfree
//! validation). A square column (W = 10 mm, L = 40 mm, E = 30 kPa, nu = 0.4) clamped at its base
//! carries a small lateral load P on its top: bending plus shear. The FEM column is a Kuhn-split
//! box mesh; the particle column is the cell-centred lattice of the same cells (particles at cell
//! centres, so the particles' volume is exactly the column's), with its bottom layer fixed and the
//! load spread over its top layer. Both are rest-linear at this load. Compared: the mean lateral
//! deflection of the top (FEM: the top face nodes; particles: the top layer).
//!
//! `cargo test --release -p palpate-core --test meshfree_vs_fem -- --nocapture` prints the table of VALIDATION.md.
use palpate_core::integrate::{static_solve, StaticOptions};
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::box_mesh;
use palpate_core::meshfree::ParticleModelBuilder;
use palpate_core::{Material, ModelBuilder, Vec3};

const W: f64 = 0.01;
const L: f64 = 0.04;
const P: f64 = 1e-4; // N: tip deflection ~ 1e-4 L, rest-linear

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap()
}

fn fem_deflection(n: usize) -> f64 {
    let cells = [n, n, 4 * n];
    let mesh = box_mesh([W, W, L], cells);
    let fixed: Vec<usize> = (0..mesh.n_nodes()).filter(|&i| mesh.points()[i].z < 1e-12).collect();
    let top: Vec<usize> = (0..mesh.n_nodes()).filter(|&i| (mesh.points()[i].z - L).abs() < 1e-12).collect();
    // Consistent nodal loads of a uniform traction on the top face: bilinear weights on the grid.
    let weight = |i: usize| {
        let p = mesh.points()[i];
        let edge = |c: f64| if c.abs() < 1e-12 || (c - W).abs() < 1e-12 { 0.5 } else { 1.0 };
        edge(p.x) * edge(p.y)
    };
    let total: f64 = top.iter().map(|&i| weight(i)).sum();
    let model = ModelBuilder::new(mesh.clone(), material()).fixed_nodes(fixed).build().unwrap();
    let mut f = vec![Vec3::zeros(); model.n_nodes()];
    for &i in &top {
        f[i] = Vec3::new(P * weight(i) / total, 0.0, 0.0);
    }
    let sol = static_solve(&model, &f, &StaticOptions { tolerance: 1e-8, ..Default::default() }).unwrap();
    top.iter().map(|&i| (sol.x[i] - mesh.points()[i]).x * weight(i)).sum::<f64>() / total
}

fn particle_deflection(n: usize) -> (f64, usize, f64) {
    let s = W / n as f64;
    let mut pts = Vec::new();
    for k in 0..4 * n {
        for j in 0..n {
            for i in 0..n {
                pts.push(Vec3::new((i as f64 + 0.5) * s, (j as f64 + 0.5) * s, (k as f64 + 0.5) * s));
            }
        }
    }
    let masses = vec![1000.0 * s * s * s; pts.len()];
    let fixed: Vec<usize> = (0..n * n).collect();
    let top: Vec<usize> = (pts.len() - n * n..pts.len()).collect();
    let model = ParticleModelBuilder::new(pts, masses, material(), 1.8 * s).fixed_particles(fixed).build().unwrap();
    let mut f = vec![Vec3::zeros(); model.n_particles()];
    for &i in &top {
        f[i] = Vec3::new(P / top.len() as f64, 0.0, 0.0);
    }
    let x = model.static_solve_linear(&f, 1e-10, 20000).unwrap();
    let defl = top.iter().map(|&i| (x[i] - model.rest_positions()[i]).x).sum::<f64>() / top.len() as f64;
    (defl, model.n_particles(), model.n_pairs() as f64 / model.n_particles() as f64)
}

#[test]
fn particle_column_matches_fem_column_and_converges() {
    let m = material();
    let i = W.powi(4) / 12.0;
    let eb = P * L.powi(3) / (3.0 * m.young() * i);
    let timo = eb + P * L / (0.8497 * m.mu() * W * W);
    println!("| cells per side | particles | mean neighbours | particles: top deflection [m] | FEM (Kuhn tets): top deflection [m] | particles / FEM | FEM / Timoshenko | particles / Timoshenko |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut diffs = vec![];
    for n in [3, 4, 6, 8, 10, 12] {
        let (dp, np, nb) = particle_deflection(n);
        let df = fem_deflection(n);
        println!("| {n} | {np} | {nb:.1} | {dp:.4e} | {df:.4e} | {:.4} | {:.4} | {:.4} |", dp / df, df / timo, dp / timo);
        diffs.push((dp / df - 1.0).abs());
    }
    println!("(Euler-Bernoulli {eb:.4e} m, Timoshenko {timo:.4e} m)");
    assert!(diffs.last().unwrap() < &0.05, "finest particle/FEM difference {:?}", diffs);
    assert!(diffs.last().unwrap() < &diffs[0], "difference does not shrink with refinement: {diffs:?}");
}
