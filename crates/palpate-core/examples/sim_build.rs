//! Compile a hybrid simulation and print its sizes: `cargo run --release --example sim_build`.
use palpate_core::hybrid::{build, shapes, HybridOptions};
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use palpate_core::runtime::{Sim, SimOptions};
use palpate_core::Material;
use std::time::Instant;

fn main() {
    let mat = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
    for (name, wall) in [
        ("ellipsoids", shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap()),
        (
            "truncated ventricle",
            shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap(),
        ),
    ] {
        let t = Instant::now();
        let m = build(&wall, &HybridOptions::default()).unwrap();
        let tb = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let support: f64 = std::env::var("SUPPORT").ok().and_then(|s| s.parse().ok()).unwrap_or(SimOptions::default().support_spacings);
        let sim = match Sim::new(m, mat, SimOptions { support_spacings: support, ..Default::default() }) {
            Ok(s) => s,
            Err(e) => {
                println!("{name}: {e}");
                continue;
            }
        };
        let ts = t.elapsed().as_secs_f64();
        let coupled = sim.coupled.iter().filter(|&&c| c).count();
        if let Ok(list) = std::env::var("INSPECT") {
            for p in list.split(',').filter_map(|s| s.parse::<usize>().ok()).filter(|&p| p < sim.n_particles()) {
                let ms = &sim.hybrid.particle_mass;
                let mean = ms.iter().sum::<f64>() / ms.len() as f64;
                println!(
                    "  particle {p} at {:?}: mass {:.3e} (mean {mean:.3e}, min {:.3e}), neighbours {}, coupled {}, tie offset {:.3e} m, fixed {}",
                    sim.hybrid.particles[p].as_slice(),
                    ms[p],
                    ms.iter().cloned().fold(f64::INFINITY, f64::min),
                    sim.particles.neighbours(p).len(),
                    sim.coupled[p],
                    sim.particle_tie.offsets()[p].norm(),
                    sim.particles.fixed()[p]
                );
            }
            println!("  held: {}", sim.particles.unsupported().len());
        }
        let worst = (0..sim.n_particles())
            .map(|i| (sim.particle_tie.position(i, &sim.hybrid.core_points) - sim.hybrid.particles[i]).norm())
            .fold(0.0, f64::max);
        println!("{name}: build {tb:.2} s, sim {ts:.2} s: core {} tets ({} fixed), {} particles ({} coupled), stable dt {:.3e} s, substeps at 1 ms {}, regions {}, tie error {worst:.1e} m",
            sim.core.n_tets(), sim.core.fixed().iter().filter(|&&f| f).count(), sim.n_particles(), coupled, sim.particles.stable_dt(), sim.particles.substeps(1e-3), sim.hybrid.n_regions());
    }
}
