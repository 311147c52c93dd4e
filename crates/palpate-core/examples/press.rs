//! The protocol's probe pressed at a chosen force, with each integrator:
//! `cargo run --release --example press -- 1350 2.0 [steps]`. Prints steps/s, iterations,
//! inverted elements, max |u|, per-step time percentiles and the distance from Newton's run.
#[path = "../tests/support/protocol.rs"]
mod protocol;

use palpate_core::integrate::Filter;
use palpate_core::{step, Integrator, ModelBuilder, State, Vec3, Workspace};
use std::time::Instant;

fn main() {
    let name = std::env::args().nth(1).unwrap_or_else(|| "1350".into());
    let force: f64 = std::env::args().nth(2).and_then(|s| s.parse().ok()).unwrap_or(0.2);
    let steps: usize = std::env::args().nth(3).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let case = protocol::load_case(&name).expect("shared meshes");
    let f_node = case.f_node * (force / protocol::FORCE);
    let tol: f64 = std::env::args().nth(4).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_TOLERANCE);
    let cap: usize = std::env::args().nth(5).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_MAX_ITERATIONS);
    let history: usize = std::env::args().nth(6).and_then(|s| s.parse().ok()).unwrap_or(Integrator::QUASI_NEWTON_HISTORY);
    let only: Option<String> = std::env::args().nth(7);
    let integrators = [
        ("newton", Integrator::newton()),
        ("quasi-newton", Integrator::BackwardEulerQuasiNewton { max_iterations: cap, tolerance: tol, history }),
        ("linear", Integrator::BackwardEulerLinear),
        ("semi-implicit", Integrator::semi_implicit()),
        ("semi-implicit stable", Integrator::SemiImplicit { filter: Filter::Stable }),
    ];
    let mut reference: Option<Vec<Vec3>> = None;
    for (label, integ) in integrators {
        if only.as_deref().is_some_and(|o| o != label && !(o.ends_with('+') && (label == "newton" || label == &o[..o.len() - 1]))) { continue; }
        let material = if std::env::var("LAW").as_deref() == Ok("nh") { protocol::material().with_law(palpate_core::material::Law::NeoHookean) } else { protocol::material() };
        let model = ModelBuilder::new(case.mesh.clone(), material).fixed_nodes(case.fixed.clone()).integrator(integ).build().unwrap();
        let mut st = State::rest(&model);
        let mut ws = Workspace::new(&model);
        let mut times = Vec::with_capacity(steps);
        let mut mean = vec![Vec3::zeros(); model.n_nodes()];
        let (mut cnt, mut umax, mut it_sum, mut it_max, mut inv_max, mut dphi_max) = (0, 0.0f64, 0usize, 0usize, 0usize, f64::MIN);
        let mut err = None;
        for k in 0..steps {
            let s = protocol::ramp((k + 1) as f64 * protocol::DT);
            for &i in &case.loaded { st.f_ext[i] = f_node * s; }
            let t = Instant::now();
            let r = step(&model, &mut st, &mut ws, protocol::DT);
            times.push(t.elapsed().as_secs_f64() * 1e6);
            let r = match r { Ok(r) => r, Err(e) => { err = Some(format!("step {k}: {e}")); break; } };
            it_sum += r.iterations; if std::env::var("TRACE").is_ok() { eprintln!("{label} {k} {} {} {:.3e} {}", r.iterations, r.evaluations, r.residual, r.inverted); } it_max = it_max.max(r.iterations); inv_max = inv_max.max(r.inverted);
            dphi_max = dphi_max.max(r.potential_change);
            let mut u_step = 0.0f64;
            for (i, (x, x0)) in st.x.iter().zip(model.mesh().points()).enumerate() {
                let u = x - x0;
                u_step = u_step.max(u.norm());
                if k >= steps / 2 { mean[i] += u; }
            }
            umax = umax.max(u_step);
            if k >= steps / 2 { cnt += 1; }
            if !(u_step < 1.0) { err = Some(format!("blew up at step {k}")); break; }
        }
        let pot = model.strain_energy(&st.x) - st.x.iter().zip(model.mesh().points()).zip(&st.f_ext).map(|((x, x0), f)| f.dot(&(x - x0))).sum::<f64>();
        eprintln!("{label}: final static potential {pot:.6e} J, kinetic {:.3e} J", model.kinetic_energy(&st.v));
        let n = times.len();
        let wall: f64 = times.iter().sum::<f64>() * 1e-6;
        times.sort_by(f64::total_cmp);
        let pct = |q: f64| times[((q * (n - 1) as f64).round() as usize).min(n - 1)];
        for m in mean.iter_mut() { *m /= cnt.max(1) as f64; }
        let rel = reference.as_ref().map(|r| {
            let num: f64 = mean.iter().zip(r).map(|(a, b)| (a - b).norm_squared()).sum::<f64>().sqrt();
            let den: f64 = r.iter().map(|b| b.norm_squared()).sum::<f64>().sqrt();
            num / den
        });
        println!("{name} {force} N {label:>21}: {:>8.0} steps/s | it mean {:.2} max {} | inverted max {} | max|u| {:.2} mm | p50 {:.0} p99 {:.0} max {:.0} us | rel vs newton {} | dphi max {:.2e} {}",
            n as f64 / wall, it_sum as f64 / n as f64, it_max, inv_max, umax * 1e3, pct(0.5), pct(0.99), times[n - 1],
            rel.map(|r| format!("{:.3}%", 100.0 * r)).unwrap_or("-".into()), dphi_max, err.unwrap_or_default());
        if reference.is_none() { reference = Some(mean); }
    }
}
