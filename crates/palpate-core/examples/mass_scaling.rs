//! What selective mass scaling buys the hybrid shell (`meshfree/mass_scaling.rs`):
//! `cargo run --release --example mass_scaling -- [ventricle|ellipsoids|MODEL.palpate]`.
//! For each quantile: the proven bound and the power-iteration `omega_max^2`, the rest sub-step
//! count of a 1 ms tick damped (paper's viscosity) and undamped, and the mass added.
use palpate_core::hybrid::{build, shapes, HybridModel, HybridOptions};
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use palpate_core::meshfree::ParticleModelBuilder;
use palpate_core::Material;
use std::time::Instant;

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "ventricle".into());
    let m = if which.ends_with(".palpate") {
        HybridModel::load(std::path::Path::new(&which)).unwrap()
    } else {
        let wall = if which == "ellipsoids" {
            shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap()
        } else {
            shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap()
        };
        build(&wall, &HybridOptions::default()).unwrap()
    };
    let el = Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 };
    println!("{which}: {} particles, spacing {:.2} mm", m.particles.len(), m.spacing * 1e3);
    println!("quantile  bound(1/s^2)  omega^2(power)  sub damped  sub undamped  scaled  added  max factor  build s");
    for q in [None, Some(0.999), Some(0.99), Some(0.98), Some(0.95), Some(0.9), Some(0.8), Some(0.7), Some(0.5)] {
        let mut row = Vec::new();
        for damped in [true, false] {
            let mat = Material::new(el, 1000.0, if damped { Damping::from_paper(0.5, 0.5) } else { Damping::NONE }).unwrap();
            let mut b = ParticleModelBuilder::new(m.particles.clone(), m.particle_mass.clone(), mat, 1.8 * m.spacing).fix_unsupported(true);
            if let Some(q) = q {
                b = b.mass_scaling(q);
            }
            let t = Instant::now();
            let p = b.build().unwrap();
            row.push((p, t.elapsed().as_secs_f64()));
        }
        let (pd, secs) = &row[0];
        let pu = &row[1].0;
        let s = pd.mass_scaling();
        println!(
            "{:>8}  {:>12.3e}  {:>14.3e}  {:>10}  {:>12}  {:>6}  {:>5.2}%  {:>10.2}  {:>7.2}",
            q.map(|q| format!("{q}")).unwrap_or("off".into()),
            s.target_rate2,
            pd.omega_max().powi(2),
            pd.substeps(1e-3),
            pu.substeps(1e-3),
            s.scaled,
            100.0 * s.added_fraction,
            s.max_factor,
            secs
        );
    }
}
