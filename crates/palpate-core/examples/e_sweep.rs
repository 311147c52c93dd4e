//! A saved hybrid model pressed by a sphere at several Young's moduli: is the force proportional
//! to E, as Hertz's is? `cargo run --release --example e_sweep -- MODEL.palpate x y z nx ny nz
//! radius_m travel_mm [E_Pa ...]` (default E: 15, 30, 60, 120 kPa; nu = 0.4, 1060 kg/m^3,
//! undamped, `DAMPED=1` the paper's damping). The sphere approaches the point `(x, y, z)` [m]
//! along the inward normal `n` from 1 mm outside its first contact (200 ticks), travels
//! `travel_mm` over 500 ticks and holds 500; prints per E the coupling springs' stiffness, the
//! indentation (travel less the contact's sink) and force averaged over the hold's second half,
//! Hertz's force there, the core's iterations and the particle sub-steps a tick.
//! VALIDATION.md ("Hertz on a hybrid slab") has the slab's figures.
use palpate_core::hybrid::HybridModel;
use palpate_core::material::{Damping, Elasticity};
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace};
use palpate_core::{Material, Vec3};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let f = |k: usize| a[k].parse::<f64>().unwrap();
    let m = HybridModel::load(std::path::Path::new(&a[1])).unwrap();
    let p = Vec3::new(f(2), f(3), f(4));
    let n = Vec3::new(f(5), f(6), f(7)).normalize();
    let r = f(8);
    let travel = f(9) * 1e-3;
    let es: Vec<f64> = if a.len() > 10 {
        a[10..].iter().map(|s| s.parse().unwrap()).collect()
    } else {
        vec![15e3, 30e3, 60e3, 120e3]
    };
    let damped = std::env::var_os("DAMPED").is_some();
    for e in es {
        let mat =
            Material::new(Elasticity::YoungPoisson { young: e, poisson: 0.4 }, 1060.0, if damped { Damping::from_paper(0.5, 0.5) } else { Damping::NONE })
                .unwrap();
        let mut opts = SimOptions { shell_fallback: None, ..SimOptions::default() };
        opts.tool.radius = r;
        let sim = Sim::new(m.clone(), mat, opts).unwrap();
        let mut st = SimState::rest(&sim);
        let mut ws = SimWorkspace::new(&sim);
        // First contact: the skin vertex the sphere meets first along n from 1 mm outside.
        let start = p - n * (r + 1e-3);
        let mut t0 = f64::INFINITY;
        for v in &sim.hybrid.outer_points {
            let q = v - start;
            let b = q.dot(&n);
            let disc = b * b - (q.norm_squared() - r * r);
            if disc >= 0.0 {
                t0 = t0.min(b - disc.sqrt());
            }
        }
        let (ramp, hold) = (500, 500);
        let (mut fs, mut pens, mut iters, mut subs, mut fail) = (0.0, 0.0, 0usize, 0usize, None);
        for j in 0..(200 + ramp + hold) {
            let s = if j < 200 {
                t0 - 1e-3 + 1e-3 * (j + 1) as f64 / 200.0
            } else {
                t0 + travel * (((j - 199) as f64) / ramp as f64).min(1.0)
            };
            match tick(&sim, &mut st, &mut ws, start + n * s, 1e-3) {
                Ok(rep) => {
                    iters += rep.core.iterations;
                    subs += rep.substeps;
                    if j >= 200 + ramp + hold / 2 {
                        fs += -rep.force.dot(&n);
                        pens += rep.max_depth;
                    }
                }
                Err(err) => {
                    fail = Some(format!("tick {j}: {err}"));
                    break;
                }
            }
        }
        let k = (hold - hold / 2) as f64;
        let (fm, pen) = (fs / k, pens / k);
        let d = travel - pen;
        let es = e / (1.0 - 0.16);
        let hertz = 4.0 / 3.0 * es * r.sqrt() * d.max(0.0).powf(1.5);
        println!(
            "E {e:>7.0} coupling {:.2} N/m: ind {:.3} mm F {fm:.4} N Hertz {hertz:.4} F/H {:.3} core it/tick {:.2} sub/tick {:.1} {}",
            sim.coupling.stiffness,
            d * 1e3,
            fm / hertz,
            iters as f64 / 1200.0,
            subs as f64 / 1200.0,
            fail.unwrap_or_default()
        );
    }
}
