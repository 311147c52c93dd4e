//! Print the core-shell exchange data of the built hybrid models (stability study).
use palpate_core::hybrid::{build, shapes, HybridOptions};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use palpate_core::runtime::{Sim, SimOptions};
use palpate_core::Material;
fn main() {
    for which in ["ventricle", "ellipsoids"] {
        let wall = if which == "ellipsoids" { shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap() } else { shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap() };
        let m = build(&wall, &HybridOptions::default()).unwrap();
        let sim = Sim::new(m, Material::myocardium(), SimOptions::default()).unwrap();
        let n = sim.core.n_nodes();
        let mut w = vec![0.0; n];
        for p in 0..sim.n_particles() { sim.particle_tie.spread_scalar(p, 1.0, &mut w); }
        let free: Vec<usize> = (0..n).filter(|&a| !sim.core.fixed()[a] && w[a] > 0.0).collect();
        let mm: Vec<f64> = free.iter().map(|&a| sim.core.masses()[a]).collect();
        let ww: Vec<f64> = free.iter().map(|&a| w[a]).collect();
        let ratio: Vec<f64> = free.iter().map(|&a| w[a] * 7.2e-7 / sim.core.masses()[a]).collect();
        println!("{which}: core nodes {n}, tied free nodes {}, node mass min/mean {:.2e}/{:.2e} kg, particles per node max/mean {:.0}/{:.0}, shell share of node mass max {:.2}, coupling k {:.2} N/m c {:.2e}, particle mass {:.2e}",
            free.len(), mm.iter().cloned().fold(f64::INFINITY, f64::min), mm.iter().sum::<f64>() / mm.len() as f64, ww.iter().cloned().fold(0.0, f64::max), ww.iter().sum::<f64>() / ww.len() as f64, ratio.iter().cloned().fold(0.0, f64::max), sim.coupling.stiffness, sim.coupling.damping, sim.particles.masses()[0]);
    }
}
