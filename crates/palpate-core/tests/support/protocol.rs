//! The benchmark case of `shared/bench/PROTOCOL.md` in Rust, for criterion benches, examples and
//! tests (the Python `palpate bench protocol` is the user-facing version). Includes a minimal
//! reader of gmsh 4.1 ASCII files (nodes and 4-node tets only): the product reads meshes with
//! meshio in Python; this reader exists so that the Rust benches can use the shared meshes.
#![allow(dead_code)]

use palpate_core::material::{Damping, Elasticity};
use palpate_core::probe::{ProbeLoad, Ramp, StepClock};
use palpate_core::{Material, TetMesh, Vec3};
use std::path::{Path, PathBuf};

pub const SCALE: f64 = 0.01; // mesh unit -> m
pub const OUTER: [f64; 3] = [2.6, 2.6, 4.2];
pub const PROBE_Z: f64 = 2.0;
pub const PROBE_R: f64 = 0.5;
pub const FORCE: f64 = 0.2;
pub const RAMP: f64 = 0.1;
pub const DT: f64 = 1e-3;

/// `shared/bench/meshes`, found from `PALPATE_SHARED` or beside the repository.
pub fn meshes_dir() -> Option<PathBuf> {
    let base = std::env::var_os("PALPATE_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"));
    let d = base.join("bench/meshes");
    d.is_dir().then_some(d)
}

/// Points (in mesh units) and tets of a mesh file.
pub type MeshArrays = (Vec<[f64; 3]>, Vec<[i64; 4]>);

/// Read a gmsh 4.1 ASCII mesh: (points in mesh units, tets).
pub fn read_msh4(path: &Path) -> Result<MeshArrays, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let mut points = Vec::new();
    let mut tags = std::collections::HashMap::new();
    let mut tets = Vec::new();
    let num = |s: &str| s.parse::<f64>().map_err(|e| format!("{}: {e}", path.display()));
    while let Some(l) = lines.next() {
        match l.trim() {
            "$Nodes" => {
                let h: Vec<usize> = lines.next().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect();
                for _ in 0..h[0] {
                    let b: Vec<usize> = lines.next().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect();
                    let k = b[3];
                    let ids: Vec<usize> = (0..k).map(|_| lines.next().unwrap_or("0").trim().parse().unwrap_or(0)).collect();
                    for id in ids {
                        let c: Vec<&str> = lines.next().unwrap_or("").split_whitespace().collect();
                        tags.insert(id, points.len());
                        points.push([num(c[0])?, num(c[1])?, num(c[2])?]);
                    }
                }
            }
            "$Elements" => {
                let h: Vec<usize> = lines.next().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect();
                for _ in 0..h[0] {
                    let b: Vec<usize> = lines.next().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect();
                    let (etype, k) = (b[2], b[3]);
                    for _ in 0..k {
                        let e: Vec<usize> = lines.next().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect();
                        if etype == 4 {
                            tets.push([tags[&e[1]] as i64, tags[&e[2]] as i64, tags[&e[3]] as i64, tags[&e[4]] as i64]);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok((points, tets))
}

pub fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap()
}

/// The protocol set-up: mesh in metres, fixed base nodes, loaded nodes and the force on each.
pub struct Case {
    pub mesh: TetMesh,
    pub fixed: Vec<usize>,
    pub loaded: Vec<usize>,
    pub f_node: Vec3,
}

pub fn case_from_mesh_units(points: &[[f64; 3]], tets: &[[i64; 4]]) -> Case {
    let fixed: Vec<usize> = (0..points.len()).filter(|&i| points[i][2] <= 1e-6).collect();
    let level = |p: &[f64; 3]| ((p[0] / OUTER[0]).powi(2) + (p[1] / OUTER[1]).powi(2) + (p[2] / OUTER[2]).powi(2)).sqrt();
    let outer: Vec<usize> = (0..points.len()).filter(|&i| (level(&points[i]) - 1.0).abs() < 1e-3).collect();
    let x = OUTER[0] * (1.0 - (PROBE_Z / OUTER[2]).powi(2)).sqrt();
    let p = Vec3::new(x, 0.0, PROBE_Z);
    let n = -Vec3::new(p.x / OUTER[0].powi(2), p.y / OUTER[1].powi(2), p.z / OUTER[2].powi(2)).normalize();
    let dist = |i: usize| (Vec3::from(points[i]) - p).norm();
    let mut loaded: Vec<usize> = outer.iter().copied().filter(|&i| dist(i) <= PROBE_R).collect();
    if loaded.is_empty() {
        loaded.push(*outer.iter().min_by(|&&a, &&b| dist(a).total_cmp(&dist(b))).expect("outer surface nodes"));
    }
    let f_node = n * (FORCE / loaded.len() as f64);
    let pts_m: Vec<[f64; 3]> = points.iter().map(|p| [p[0] * SCALE, p[1] * SCALE, p[2] * SCALE]).collect();
    let (mesh, _) = TetMesh::from_arrays(&pts_m, tets).expect("valid protocol mesh");
    Case { mesh, fixed, loaded, f_node }
}

pub fn load_case(name: &str) -> Option<Case> {
    let dir = meshes_dir()?;
    let (p, t) = read_msh4(&dir.join(format!("lv_{name}.msh"))).ok()?;
    Some(case_from_mesh_units(&p, &t))
}

/// The protocol's probe load scaled to `force` \[N\] (the protocol's is [`FORCE`]), ramped
/// over [`RAMP`] from `start` \[s\] (the one ramp convention: `palpate_core::probe`).
pub fn probe_load(case: &Case, force: f64, start: f64) -> ProbeLoad {
    let total = case.f_node * (case.loaded.len() as f64 * force / FORCE);
    ProbeLoad::new(case.mesh.n_nodes(), case.loaded.clone(), total, Ramp { start, duration: RAMP }).expect("valid protocol load")
}

/// A wall clock for timed runs (examples and benches; the core has none).
pub struct WallClock(std::time::Instant);

impl WallClock {
    pub fn new() -> WallClock {
        WallClock(std::time::Instant::now())
    }
}

impl StepClock for WallClock {
    fn now(&mut self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
}
