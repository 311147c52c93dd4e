//! Points tied to core faces: the kinematics by which the skin (outer surface) and the inactive
//! particles follow the FEM core, and the transpose by which forces on them reach the core nodes
//! (paper §4, §6.1).
//!
//! A point `p` is tied to a core face `(a, b, c)` by barycentric weights `w` (`w_a + w_b + w_c =
//! 1`) and a rest offset `o` (world frame): `x_p = w_a x_a + w_b x_b + w_c x_c + o`. The map is
//! affine in the core positions with Jacobian `w_k I` per face node, so a force `f` on the point
//! does the virtual work of the forces `w_k f` on the face nodes: spreading by the same weights is
//! the exact transpose (energy-consistent), and since the weights sum to one the spread forces sum
//! to `f` (linear momentum exact). The offset is not rotated with the face: a rigid rotation of the
//! organ would shear the tied points by `|o|` times the angle. The ventricle's base is held, so its
//! faces rotate little; the exactness of the transpose is worth more here (a rotated offset would
//! make the spread forces non-conservative by `|o| / face size`, which is not small in a shell of
//! several lattice spacings).

use crate::math::Vec3;
use crate::spatial::closest_on_triangle;

/// Points tied to core faces. All arrays `(n_points)`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Embedding {
    /// The three core nodes of each point's face.
    nodes: Vec<[u32; 3]>,
    /// Barycentric weights on them (sum 1).
    weights: Vec<[f64; 3]>,
    /// Rest offset from the weighted face point to the point \[m\].
    offset: Vec<Vec3>,
}

impl Embedding {
    /// Ties each `rest[i]` to core face `face_of[i]` of `faces` (node triples into `core`): the
    /// closest point of the face gives the weights, the remainder the offset.
    pub fn project(core: &[Vec3], faces: &[[usize; 3]], face_of: &[u32], rest: &[Vec3]) -> Embedding {
        let mut e = Embedding::default();
        for (p, &f) in rest.iter().zip(face_of) {
            let t = faces[f as usize];
            let (a, b, c) = (core[t[0]], core[t[1]], core[t[2]]);
            let (_, w) = closest_on_triangle(p, &a, &b, &c);
            let anchor = w[0] * a + w[1] * b + w[2] * c;
            e.nodes.push(t.map(|i| i as u32));
            e.weights.push(w);
            e.offset.push(p - anchor);
        }
        e
    }

    /// Ties with given faces, weights and offsets (the skin of a [`crate::hybrid::HybridModel`]).
    pub fn from_parts(faces: &[[usize; 3]], face_of: &[u32], weights: &[[f64; 3]], offset: &[Vec3]) -> Embedding {
        Embedding {
            nodes: face_of.iter().map(|&f| faces[f as usize].map(|i| i as u32)).collect(),
            weights: weights.to_vec(),
            offset: offset.to_vec(),
        }
    }

    /// Number of tied points.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// No tied points?
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The face nodes and weights of point `i`.
    #[inline]
    pub fn tie(&self, i: usize) -> ([u32; 3], [f64; 3]) {
        (self.nodes[i], self.weights[i])
    }

    /// Position of point `i` for core positions `x` \[m\].
    #[inline]
    pub fn position(&self, i: usize, x: &[Vec3]) -> Vec3 {
        self.interpolate(i, x) + self.offset[i]
    }

    /// The weighted face value at point `i` (a velocity, a displacement) of a core field `u`.
    #[inline]
    pub fn interpolate(&self, i: usize, u: &[Vec3]) -> Vec3 {
        let (n, w) = (self.nodes[i], self.weights[i]);
        w[0] * u[n[0] as usize] + w[1] * u[n[1] as usize] + w[2] * u[n[2] as usize]
    }

    /// Adds a force `f` on point `i` to the core forces `out` (the transpose of [`Self::position`]).
    #[inline]
    pub fn spread(&self, i: usize, f: Vec3, out: &mut [Vec3]) {
        let (n, w) = (self.nodes[i], self.weights[i]);
        for k in 0..3 {
            out[n[k] as usize] += w[k] * f;
        }
    }

    /// Adds a scalar `s` carried by point `i` (a mass, a spring's weight) to the core nodes'
    /// `out`, shared by the tie's weights.
    #[inline]
    pub fn spread_scalar(&self, i: usize, s: f64, out: &mut [f64]) {
        let (n, w) = (self.nodes[i], self.weights[i]);
        for k in 0..3 {
            out[n[k] as usize] += w[k] * s;
        }
    }

    /// The rest offsets \[m\].
    pub fn offsets(&self) -> &[Vec3] {
        &self.offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> (Vec<Vec3>, Vec<[usize; 3]>) {
        (vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(5.0, 5.0, 5.0)], vec![[0, 1, 2]])
    }

    #[test]
    fn rest_positions_are_reproduced_and_translations_carried() {
        let (core, faces) = tri();
        let rest = [Vec3::new(0.2, 0.3, 0.5), Vec3::new(2.0, -1.0, -0.1), Vec3::new(0.0, 0.0, 0.0)];
        let e = Embedding::project(&core, &faces, &[0, 0, 0], &rest);
        for (i, p) in rest.iter().enumerate() {
            assert!((e.position(i, &core) - p).norm() < 1e-14);
            let (_, w) = e.tie(i);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-14 && w.iter().all(|&x| x >= -1e-14));
        }
        let shift = Vec3::new(0.1, -0.2, 0.3);
        let moved: Vec<Vec3> = core.iter().map(|x| x + shift).collect();
        for (i, p) in rest.iter().enumerate() {
            assert!((e.position(i, &moved) - (p + shift)).norm() < 1e-14);
        }
    }

    #[test]
    fn spreading_is_the_transpose_and_keeps_the_total() {
        let (core, faces) = tri();
        let e = Embedding::project(&core, &faces, &[0], &[Vec3::new(0.25, 0.25, 0.1)]);
        let f = Vec3::new(1.0, -2.0, 0.5);
        let mut out = vec![Vec3::zeros(); core.len()];
        e.spread(0, f, &mut out);
        assert!((out.iter().sum::<Vec3>() - f).norm() < 1e-15);
        // Virtual work: f . dx_p = sum_k out_k . dx_k for any core motion dx.
        let dx: Vec<Vec3> = (0..core.len()).map(|k| Vec3::new(0.3 * k as f64, -0.1, 0.7 - k as f64)).collect();
        let lhs = f.dot(&e.interpolate(0, &dx));
        let rhs: f64 = out.iter().zip(&dx).map(|(a, b)| a.dot(b)).sum();
        assert!((lhs - rhs).abs() < 1e-14);
    }
}
