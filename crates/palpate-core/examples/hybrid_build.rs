//! Build the hybrid model of a shipped wall and print what it holds:
//! `cargo run --release --example hybrid_build -- [ellipsoids|ventricle] [radial]`.
use palpate_core::hybrid::{build, shapes, HybridOptions, Projection};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "ellipsoids".into());
    let radial = std::env::args().any(|a| a == "radial");
    let wall = match which.as_str() {
        "rodero" => load_raw("/tmp/rodero.bin"),
        "ventricle" => shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap(),
        _ => shapes::ellipsoids([0.020, 0.020, 0.035], [0.026, 0.026, 0.042], 5).unwrap(),
    };
    if std::env::args().any(|a| a == "debug") { debug_field(&wall); debug_core(&wall); return; }
    let mut o = HybridOptions::default();
    o.core_triangles = 0;
    if radial {
        o.projection = Projection::Radial;
    }
    for a in std::env::args() {
        if let Some(v) = a.strip_prefix("tri=") { o.core_triangles = v.parse().unwrap(); }
        if let Some(v) = a.strip_prefix("frac=") { o.core_fraction = v.parse().unwrap(); }
        if let Some(v) = a.strip_prefix("layers=") { o.core_layers = v.parse().unwrap(); }
    }
    let m = match build(&wall, &o) { Ok(m) => m, Err(e) => { println!("ERR {e}"); return; } };
    if std::env::args().any(|a| a == "diag") { diagnose(&m, &wall); levels(&m); }
    let s = &m.stats;
    println!("{which}: {} wall triangles, wall volume {:.2} mL", wall.surface.n_triangles(), m.wall_volume * 1e6);
    println!("core: {} tets, {} nodes, {} base nodes, volume {:.2} mL, min dihedral {:.1} deg, volume ratio {:.2e}", m.core_tets.len(), m.core_points.len(), m.core_base_nodes.len(), m.core_volume() * 1e6, m.core_quality.min_dihedral_deg, m.core_quality.min_volume / m.core_quality.max_volume);
    println!("particles: {} at {:.3} mm, shell {:.2} mL; core + shell = {:.4} of the wall", m.particles.len(), m.spacing * 1e3, m.shell_volume() * 1e6, (m.core_volume() + m.shell_volume()) / m.wall_volume);
    let sizes: Vec<usize> = (0..m.n_regions()).map(|r| m.region_len(r)).collect();
    println!("regions: {}, particles per region min {} median {} max {}", m.n_regions(), sizes.iter().min().unwrap(), { let mut v = sizes.clone(); v.sort(); v[v.len() / 2] }, sizes.iter().max().unwrap());
    println!("time: field {:.3} s ({} CG it), core {:.3} s, particles {:.3} s, regions+skin {:.3} s, total {:.3} s", s.field_s, s.field_iterations, s.core_s, s.particles_s, s.regions_s, s.total_s);
    println!("fallbacks: particle->outer {}, particle->core {}, skin {}", s.fallback_particle_outer, s.fallback_particle_core, s.fallback_skin);
}

#[allow(dead_code)]
fn debug_field(wall: &palpate_core::hybrid::Wall) {
    use palpate_core::hybrid::geometry::TriangleGrid;
    let s = &wall.surface;
    let g = TriangleGrid::new(s.points(), s.triangles(), 0.004);
    let f = palpate_core::hybrid::transmural::solve(s, &wall.parts, 0.001, &g);
    let nw = f.wall.iter().filter(|&&w| w).count();
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for v in 0..f.wall.len() { if f.wall[v] { lo = lo.min(f.phi[v]); hi = hi.max(f.phi[v]); } }
    println!("grid {:?} wall voxels {nw} phi [{lo}, {hi}] it {} res {:e} centre {:?}", f.grid.dims, f.iterations, f.residual, f.centre);
    for z in [0.0, 0.021, 0.022, 0.024, 0.026, 0.027] { let p = palpate_core::Vec3::new(z, 0.0, 0.0); println!("x={z}: phi {:.3} dir {:?}", f.phi_at(&p), f.dir_at(&p, palpate_core::hybrid::Projection::Transmural)); }
}

#[allow(dead_code)]
pub fn diagnose(m: &palpate_core::hybrid::HybridModel, wall: &palpate_core::hybrid::Wall) {
    use palpate_core::Vec3;
    // Core volume outside the wall, by sampling each tet.
    let (mut inside, mut total) = (0.0, 0.0);
    let k = 6;
    for t in &m.core_tets {
        let p: Vec<Vec3> = t.iter().map(|&v| m.core_points[v]).collect();
        let vol = palpate_core::mesh::signed_volume(&p[0], &p[1], &p[2], &p[3]);
        let mut n = 0; let mut ni = 0;
        for a in 0..=k { for b in 0..=k-a { for c in 0..=k-a-b { let d = k - a - b - c;
            let x = (p[0] * (a as f64 + 0.25) + p[1] * (b as f64 + 0.25) + p[2] * (c as f64 + 0.25) + p[3] * (d as f64 + 0.25)) / (k as f64 + 1.0);
            n += 1; if wall.surface.contains_parity(&x) { ni += 1; } }}}
        inside += vol * ni as f64 / n as f64; total += vol;
    }
    let bnd = palpate_core::hybrid::shapes::oriented_boundary(&palpate_core::TetMesh::from_arrays(&m.core_points.iter().map(|p| [p.x,p.y,p.z]).collect::<Vec<_>>(), &m.core_tets.iter().map(|t| [t[0] as i64,t[1] as i64,t[2] as i64,t[3] as i64]).collect::<Vec<_>>()).unwrap().0);
    let bv: f64 = bnd.iter().map(|f| m.core_points[f[0]].dot(&m.core_points[f[1]].cross(&m.core_points[f[2]])) / 6.0).sum();
    println!("core volume {:.3} mL, inside wall {:.3} mL ({:.1}%), boundary-enclosed {:.3} mL", total*1e6, inside*1e6, 100.0*inside/total, bv*1e6);
}

#[allow(dead_code)]
pub fn levels(m: &palpate_core::hybrid::HybridModel) {
    let l = |p: &palpate_core::Vec3, a: [f64;3]| ((p.x/a[0]).powi(2)+(p.y/a[1]).powi(2)+(p.z/a[2]).powi(2)).sqrt();
    let n = m.core_points.len() / 2;
    for v in (0..n).step_by(7) {
        let (b, t) = (m.core_points[v], m.core_points[v + n]);
        println!("v{v}: bottom inner-level {:.4} top inner-level {:.4} outer-level {:.4}", l(&b,[0.02,0.02,0.035]), l(&t,[0.02,0.02,0.035]), l(&t,[0.026,0.026,0.042]));
    }
}

#[allow(dead_code)]
pub fn debug_core(wall: &palpate_core::hybrid::Wall) {
    use palpate_core::mesh::simplify::simplify;
    use palpate_core::hybrid::WallPart;
    let s = &wall.surface;
    let mut map = std::collections::HashMap::new();
    let (mut pts, mut tris) = (vec![], vec![]);
    for (t, tri) in s.triangles().iter().enumerate() {
        if wall.parts[t] != WallPart::Inner { continue; }
        let mut nt = [0; 3];
        for (k, &v) in tri.iter().enumerate() { nt[k] = *map.entry(v).or_insert_with(|| { pts.push(s.points()[v]); pts.len() - 1 }); }
        tris.push(nt);
    }
    let c = simplify(&pts, &tris, 64);
    println!("inner part: {} pts {} tris -> {} pts {} tris, boundary {}", pts.len(), tris.len(), c.points.len(), c.triangles.len(), c.boundary.iter().filter(|&&b| b).count());
    for (i, t) in c.triangles.iter().enumerate().take(6) {
        let (a, b, d) = (c.points[t[0]], c.points[t[1]], c.points[t[2]]);
        println!("tri {i} {:?} area {:e} z {:.4} {:.4} {:.4}", t, (b - a).cross(&(d - a)).norm() / 2.0, a.z, b.z, d.z);
    }
}

#[allow(dead_code)]
pub fn load_raw(path: &str) -> palpate_core::hybrid::Wall {
    let b = std::fs::read(path).unwrap();
    let rd = |o: usize| i64::from_le_bytes(b[o..o + 8].try_into().unwrap());
    let (np, nt) = (rd(0) as usize, rd(8) as usize);
    let mut off = 16;
    let pts: Vec<[f64; 3]> = (0..np).map(|i| { let o = off + 24 * i; [0, 1, 2].map(|k| f64::from_le_bytes(b[o + 8 * k..o + 8 * k + 8].try_into().unwrap())) }).collect();
    off += 24 * np;
    let tris: Vec<[i64; 3]> = (0..nt).map(|i| { let o = off + 24 * i; [0, 1, 2].map(|k| rd(o + 8 * k)) }).collect();
    off += 24 * nt;
    let parts = (0..nt).map(|i| match b[off + i] { 0 => palpate_core::hybrid::WallPart::Inner, 1 => palpate_core::hybrid::WallPart::Outer, _ => palpate_core::hybrid::WallPart::Base }).collect();
    let (s, _) = palpate_core::mesh::TriSurface::from_arrays(&pts, &tris).unwrap();
    palpate_core::hybrid::Wall::tagged(s, parts).unwrap()
}
