//! The probe set-up the hybrid examples share (included with `#[path = "support/mod.rs"]`; not an
//! example itself): the two shipped walls built with the default options, the protocol's tissue,
//! the probe point, the press-hold-slide-release path and tick-time percentiles. One copy, so that
//! `touch`, `press2n` and `tick_profile` press where and how the others (and
//! tests/runtime_hand.rs) do.
#![allow(dead_code)] // each example uses a part

use palpate_core::hybrid::{build, shapes, HybridModel, HybridOptions};
use palpate_core::material::{Damping, Elasticity};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use palpate_core::runtime::Sim;
use palpate_core::{Material, Vec3};

/// The paper's ellipsoids (`"ellipsoids"`) or, for any other name, the synthetic ventricle
/// (96 x 24), built with the default options.
pub fn wall_model(which: &str) -> HybridModel {
    let wall = if which == "ellipsoids" {
        shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap()
    } else {
        shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap()
    };
    build(&wall, &HybridOptions::default()).unwrap()
}

/// Myocardium as the protocol has it (E = 30 kPa, nu = 0.4, 1000 kg/m^3), with the paper's
/// damping phi = psi = 0.5 Pa s when `damped`.
pub fn tissue(damped: bool) -> Material {
    let damping = if damped { Damping::from_paper(0.5, 0.5) } else { Damping::NONE };
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, damping).unwrap()
}

/// The protocol's probe: the outer vertex on the `+x` side nearest `(x_max, 0, z)` \[m\], and
/// the outward horizontal (radial) normal there.
pub fn probe(sim: &Sim, z: f64) -> (Vec3, Vec3) {
    let outer = &sim.hybrid.outer_points;
    let p = *outer
        .iter()
        .filter(|q| q.x > 0.0)
        .min_by(|a, b| (a.y.powi(2) + (a.z - z).powi(2)).total_cmp(&(b.y.powi(2) + (b.z - z).powi(2))))
        .unwrap();
    (p, Vec3::new(p.x, p.y, 0.0).normalize())
}

/// Tick `k` of a press-hold-slide-release path with phases `[press, hold, slide, release]`
/// ticks long: `(depth, slide)` \[m\]. The depth goes from -2 mm (off the skin) to `depth` over
/// the press, holds, stays over the slide while the slide goes from 0 to `slide`, and goes back
/// to -2 mm over the release.
pub fn press_path(k: usize, [press, hold, slide_ticks, release]: [usize; 4], depth: f64, slide: f64) -> (f64, f64) {
    if k < press {
        (-2e-3 + (depth + 2e-3) * k as f64 / press as f64, 0.0)
    } else if k < press + hold {
        (depth, 0.0)
    } else if k < press + hold + slide_ticks {
        (depth, slide * (k - press - hold) as f64 / slide_ticks as f64)
    } else {
        (depth - (depth + 2e-3) * (k - press - hold - slide_ticks) as f64 / release as f64, slide)
    }
}

/// The `q` quantile of `sorted` (ascending, not empty), the nearest rank.
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((q * (sorted.len() - 1) as f64).round() as usize).min(sorted.len() - 1)]
}
