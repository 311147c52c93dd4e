//! Build the hybrid model of a shipped wall and print what it holds:
//! `cargo run --release --example hybrid_build -- [ellipsoids|ventricle] [radial] [diag] [tri=N] [frac=F] [layers=N]`
//! (`diag`: how much of the core lies in the wall; the real ventricle: `palpate build --shape rodero`).
use palpate_core::hybrid::{build, shapes, HybridOptions, Projection};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "ellipsoids".into());
    let radial = std::env::args().any(|a| a == "radial");
    let wall = match which.as_str() {
        "ventricle" => shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap(),
        _ => shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap(),
    };
    let mut o = HybridOptions { core_triangles: 0, ..HybridOptions::default() };
    if radial {
        o.projection = Projection::Radial;
    }
    for a in std::env::args() {
        if let Some(v) = a.strip_prefix("tri=") {
            o.core_triangles = v.parse().unwrap();
        }
        if let Some(v) = a.strip_prefix("frac=") {
            o.core_fraction = v.parse().unwrap();
        }
        if let Some(v) = a.strip_prefix("layers=") {
            o.core_layers = v.parse().unwrap();
        }
    }
    let m = match build(&wall, &o) {
        Ok(m) => m,
        Err(e) => {
            println!("ERR {e}");
            return;
        }
    };
    if std::env::args().any(|a| a == "diag") {
        diagnose(&m, &wall);
    }
    let s = &m.stats;
    println!("{which}: {} wall triangles, wall volume {:.2} mL", wall.surface.n_triangles(), m.wall_volume * 1e6);
    println!(
        "core: {} tets, {} nodes, {} base nodes, volume {:.2} mL, min dihedral {:.1} deg, volume ratio {:.2e}",
        m.core_tets.len(),
        m.core_points.len(),
        m.core_base_nodes.len(),
        m.core_volume() * 1e6,
        m.core_quality.min_dihedral_deg,
        m.core_quality.min_volume / m.core_quality.max_volume
    );
    println!(
        "particles: {} at {:.3} mm, shell {:.2} mL; core + shell = {:.4} of the wall",
        m.particles.len(),
        m.spacing * 1e3,
        m.shell_volume() * 1e6,
        (m.core_volume() + m.shell_volume()) / m.wall_volume
    );
    let sizes: Vec<usize> = (0..m.n_regions()).map(|r| m.region_len(r)).collect();
    println!(
        "regions: {}, particles per region min {} median {} max {}",
        m.n_regions(),
        sizes.iter().min().unwrap(),
        {
            let mut v = sizes.clone();
            v.sort();
            v[v.len() / 2]
        },
        sizes.iter().max().unwrap()
    );
    println!(
        "time: field {:.3} s ({} CG it), core {:.3} s, particles {:.3} s, regions+skin {:.3} s, total {:.3} s",
        s.field_s, s.field_iterations, s.core_s, s.particles_s, s.regions_s, s.total_s
    );
    println!("fallbacks: particle->outer {}, particle->core {}, skin {}", s.fallback_particle_outer, s.fallback_particle_core, s.fallback_skin);
}

fn diagnose(m: &palpate_core::hybrid::HybridModel, wall: &palpate_core::hybrid::Wall) {
    use palpate_core::Vec3;
    // Core volume outside the wall, by sampling each tet.
    let (mut inside, mut total) = (0.0, 0.0);
    let k = 6;
    for t in &m.core_tets {
        let p: Vec<Vec3> = t.iter().map(|&v| m.core_points[v]).collect();
        let vol = palpate_core::mesh::signed_volume(&p[0], &p[1], &p[2], &p[3]);
        let mut n = 0;
        let mut ni = 0;
        for a in 0..=k {
            for b in 0..=k - a {
                for c in 0..=k - a - b {
                    let d = k - a - b - c;
                    let x = (p[0] * (a as f64 + 0.25) + p[1] * (b as f64 + 0.25) + p[2] * (c as f64 + 0.25) + p[3] * (d as f64 + 0.25)) / (k as f64 + 1.0);
                    n += 1;
                    if wall.surface.contains_parity(&x) {
                        ni += 1;
                    }
                }
            }
        }
        inside += vol * ni as f64 / n as f64;
        total += vol;
    }
    let bnd = palpate_core::mesh::boundary_faces(&m.core_points, &m.core_tets);
    let bv: f64 = bnd.iter().map(|f| m.core_points[f[0]].dot(&m.core_points[f[1]].cross(&m.core_points[f[2]])) / 6.0).sum();
    println!(
        "core volume {:.3} mL, inside wall {:.3} mL ({:.1}%), boundary-enclosed {:.3} mL",
        total * 1e6,
        inside * 1e6,
        100.0 * inside / total,
        bv * 1e6
    );
}
