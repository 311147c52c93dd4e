//! The shipped hybrid walls the tests build, once per test binary: the paper's concentric
//! ellipsoids and the synthetic truncated ventricle of the benchmark protocol (as the Python
//! `build_shape`), with their hybrid models at the default options.
#![allow(dead_code)]

use palpate_core::hybrid::{build, shapes, HybridModel, HybridOptions, Wall};
use palpate_core::mesh::generate::TruncatedEllipsoidWall;
use std::sync::OnceLock;

/// The paper's ellipsoids: inner and outer semi-axes [m].
pub const INNER: [f64; 3] = [0.020, 0.020, 0.035];
pub const OUTER: [f64; 3] = [0.026, 0.026, 0.042];

/// The ellipsoids' wall and its hybrid model.
pub fn ellipsoids() -> &'static (Wall, HybridModel) {
    static M: OnceLock<(Wall, HybridModel)> = OnceLock::new();
    M.get_or_init(|| {
        let wall = shapes::ellipsoids(INNER, OUTER, 5).unwrap();
        let m = build(&wall, &HybridOptions::default()).unwrap();
        (wall, m)
    })
}

/// The ellipsoids' hybrid model with the paper's core (64 coarse triangles, 192 tets; Table 1
/// has 188): a softer core that bends far under a gentle press, for the tests of the runtime's
/// bookkeeping that need the core to carry the skin a long way (whole-skin refreshes).
pub fn ellipsoids_papers_core() -> &'static HybridModel {
    static M: OnceLock<HybridModel> = OnceLock::new();
    M.get_or_init(|| build(&ellipsoids().0, &HybridOptions { core_triangles: 64, ..HybridOptions::default() }).unwrap())
}

/// The synthetic truncated ventricle (96 x 24) and its hybrid model.
pub fn ventricle() -> &'static (Wall, HybridModel) {
    static M: OnceLock<(Wall, HybridModel)> = OnceLock::new();
    M.get_or_init(|| {
        let wall = shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap();
        let m = build(&wall, &HybridOptions::default()).unwrap();
        (wall, m)
    })
}
