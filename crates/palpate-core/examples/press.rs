//! The protocol's probe pressed at a chosen force, with each integrator:
//! `cargo run --release --example press -- 1350 2.0 [steps tol cap history only]`. Prints
//! steps/s, iterations, inverted elements, max |u|, per-step time percentiles and the distance
//! from Newton's run. `only` names one integrator (`label+` adds Newton as the reference);
//! `LAW=nh` uses the Neo-Hookean law.
#[path = "../tests/support/protocol.rs"]
mod protocol;

use palpate_core::integrate::Filter;
use palpate_core::probe::{run_probe, ProbeOptions};
use palpate_core::{Integrator, ModelBuilder, State, Vec3, Workspace};

fn main() {
    let arg = |k: usize| std::env::args().nth(k);
    let name = arg(1).unwrap_or_else(|| "1350".into());
    let force: f64 = arg(2).and_then(|s| s.parse().ok()).unwrap_or(0.2);
    let steps: usize = arg(3).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let case = protocol::load_case(&name).expect("shared meshes");
    let tol: f64 = arg(4).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_TOLERANCE);
    let cap: usize = arg(5).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_MAX_ITERATIONS);
    let history: usize = arg(6).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_HISTORY);
    let only: Option<String> = arg(7);
    let integrators = [
        ("newton", Integrator::newton()),
        ("quasi-newton", Integrator::BackwardEulerQuasiNewton { max_iterations: cap, tolerance: tol, history }),
        ("linear", Integrator::BackwardEulerLinear),
        ("semi-implicit", Integrator::semi_implicit()),
        ("semi-implicit stable", Integrator::SemiImplicit { filter: Filter::Stable }),
    ];
    let mut reference: Option<Vec<Vec3>> = None;
    for (label, integ) in integrators {
        if only.as_deref().is_some_and(|o| o != label && !(o.ends_with('+') && (label == "newton" || label == &o[..o.len() - 1]))) {
            continue;
        }
        let material = if std::env::var("LAW").as_deref() == Ok("nh") {
            protocol::material().with_law(palpate_core::material::Law::NeoHookean)
        } else {
            protocol::material()
        };
        let model = ModelBuilder::new(case.mesh.clone(), material).fixed_nodes(case.fixed.clone()).integrator(integ).build().unwrap();
        let mut st = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let load = [protocol::probe_load(&case, force, 0.0)];
        let run = run_probe(&model, &mut st, &mut ws, &load, &ProbeOptions::new(steps, protocol::DT, f64::INFINITY), &mut protocol::WallClock::new());
        let pot = model.strain_energy(&st.x) - st.x.iter().zip(model.mesh().points()).zip(&st.f_ext).map(|((x, x0), f)| f.dot(&(x - x0))).sum::<f64>();
        eprintln!("{label}: final static potential {pot:.6e} J, kinetic {:.3e} J", model.kinetic_energy(&st.v));
        let n = run.steps.max(1);
        let mut times: Vec<f64> = run.step_s.iter().map(|s| s * 1e6).collect();
        times.sort_by(f64::total_cmp);
        let pct = |q: f64| times.get(((q * (n - 1) as f64).round() as usize).min(n - 1)).copied().unwrap_or(f64::NAN);
        let rel = reference.as_ref().map(|r| {
            let num: f64 = run.mean_disp.iter().zip(r).map(|(a, b)| (a - b).norm_squared()).sum::<f64>().sqrt();
            let den: f64 = r.iter().map(|b| b.norm_squared()).sum::<f64>().sqrt();
            num / den
        });
        let t = &run.totals;
        println!("{name} {force} N {label:>21}: {:>8.0} steps/s | it mean {:.2} max {} | inverted max {} | max|u| {:.2} mm | p50 {:.0} p99 {:.0} max {:.0} us | rel vs newton {} | {}",
            run.steps as f64 / run.wall_s, t.mean_iterations(), t.max_iterations, t.max_inverted, run.max_disp * 1e3, pct(0.5), pct(0.99), pct(1.0),
            rel.map(|r| format!("{:.3}%", 100.0 * r)).unwrap_or("-".into()), run.stop.map(|s| s.to_string()).unwrap_or_default());
        if reference.is_none() {
            reference = Some(run.mean_disp);
        }
    }
}
