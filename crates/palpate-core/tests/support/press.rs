//! Where the hybrid tests press: a point of the outer surface and its outward direction.
#![allow(dead_code)]

use palpate_core::Vec3;

/// The outer vertex a third of the way through `outer` \[m\] and the direction from the
/// surface's centroid to it (outward for the convex walls of the tests).
pub fn press_point(outer: &[Vec3]) -> (Vec3, Vec3) {
    let centroid = outer.iter().sum::<Vec3>() / outer.len() as f64;
    let p0 = outer[outer.len() / 3];
    (p0, (p0 - centroid).normalize())
}
