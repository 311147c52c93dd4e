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

/// The synthetic truncated ventricle (96 x 24) and its hybrid model.
pub fn ventricle() -> &'static (Wall, HybridModel) {
    static M: OnceLock<(Wall, HybridModel)> = OnceLock::new();
    M.get_or_init(|| {
        let wall = shapes::truncated_ventricle(&TruncatedEllipsoidWall { circumferential: 96, longitudinal: 24, ..Default::default() }).unwrap();
        let m = build(&wall, &HybridOptions::default()).unwrap();
        (wall, m)
    })
}
