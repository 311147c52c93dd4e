//! Points tied to core faces: the kinematics by which the skin (outer surface) and the inactive
//! particles follow the FEM core, and the transpose by which forces on them reach the core nodes
//! (paper §4, §6.1).
//!
//! A point `p` is tied to a core face `(a, b, c)` by barycentric weights `w` (`w_a + w_b + w_c =
//! 1`) and an offset `o` from the weighted face point, held in the face's own frame `(e1, e2, n)`
//! (`e1` along `b - a`, `n` the face normal): `x_p = w_a x_a + w_b x_b + w_c x_c + R(x) o`, `R`
//! the face frame's rotation. The offset turns with its face: when the organ bends (a closed wall
//! held at its lower part, pressed above; the ventricle's wall under a deep press) the tied shell
//! turns with the core rather than shearing by `|o|` times the angle. (Unrotated world-frame
//! offsets, the first version, sheared the ellipsoids' shell under a 3-4 mm press until its
//! particles diverged.)
//!
//! A force `f` on the point does the virtual work of forces on the face nodes: `w_k f` from the
//! weighted point, plus the turning offset's share (`(d(R o)/dx_k)^T f`, [`Embedding::spread`]).
//! The spread is the exact transpose of the map, so forces derived from an energy of tied points
//! stay derived from an energy of the core; and since the map is translation-invariant (a shift
//! of the face shifts the point) the shares sum to `f`: linear momentum is exact.

use crate::math::{Mat3, Vec3};
use crate::spatial::closest_on_triangle;

/// Points tied to core faces. All arrays `(n_points)`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Embedding {
    /// The three core nodes of each point's face, and the face's index.
    nodes: Vec<[u32; 3]>,
    face: Vec<u32>,
    /// Barycentric weights on them (sum 1).
    weights: Vec<[f64; 3]>,
    /// Offset from the weighted face point to the point in the face's frame `(e1, e2, n)` \[m\].
    offset: Vec<Vec3>,
    /// The same offset in the world frame at rest (where the face's frame is degenerate).
    rest_offset: Vec<Vec3>,
}

/// The frames of the core faces `faces` at core positions `x` into `out` `(n_faces)` (see
/// [`Embedding::position_framed`]: one frame per face, shared by every point on it).
pub fn face_frames(x: &[Vec3], faces: &[[usize; 3]], out: &mut [Option<Mat3>]) {
    for (o, f) in out.iter_mut().zip(faces) {
        *o = frame(&x[f[0]], &x[f[1]], &x[f[2]]);
    }
}

/// [`face_frames`] and each frame's rate `dR/dt` for core velocities `v` into `rates` (see
/// [`Embedding::velocity_framed`]).
pub fn face_frames_and_rates(x: &[Vec3], v: &[Vec3], faces: &[[usize; 3]], out: &mut [Option<Mat3>], rates: &mut [Mat3]) {
    for ((o, r), f) in out.iter_mut().zip(rates.iter_mut()).zip(faces) {
        let [a, b, c] = f.map(|k| x[k]);
        let [va, vb, vc] = f.map(|k| v[k]);
        *o = frame(&a, &b, &c);
        *r = frame_rate(&a, &b, &c, &va, &vb, &vc).unwrap_or_else(Mat3::zeros);
    }
}

/// `dR/dt` of face `(a, b, c)`'s frame for vertex velocities `(va, vb, vc)`: the columns
/// `(de1, de2, dn)`; `None` for a degenerate face.
#[inline]
fn frame_rate(a: &Vec3, b: &Vec3, c: &Vec3, va: &Vec3, vb: &Vec3, vc: &Vec3) -> Option<Mat3> {
    let (e, f) = (b - a, c - a);
    let m = e.cross(&f);
    let (le, lm) = (e.norm(), m.norm());
    if !(le > 0.0 && lm > 1e-30 * le * le && lm.is_finite()) {
        return None;
    }
    let (de, df) = (vb - va, vc - va);
    let (e1, nn) = (e / le, m / lm);
    let de1 = (de - e1 * e1.dot(&de)) / le;
    let dm = de.cross(&f) + e.cross(&df);
    let dn = (dm - nn * nn.dot(&dm)) / lm;
    let de2 = dn.cross(&e1) + nn.cross(&de1);
    Some(Mat3::from_columns(&[de1, de2, dn]))
}

/// The orthonormal frame `(e1, e2, n)` of face `(a, b, c)` as matrix columns, or `None` for a
/// degenerate face.
#[inline]
fn frame(a: &Vec3, b: &Vec3, c: &Vec3) -> Option<Mat3> {
    let e = b - a;
    let m = e.cross(&(c - a));
    let (le, lm) = (e.norm(), m.norm());
    if !(le > 0.0 && lm > 1e-30 * le * le && lm.is_finite()) {
        return None;
    }
    let (e1, n) = (e / le, m / lm);
    Some(Mat3::from_columns(&[e1, n.cross(&e1), n]))
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
            e.push(t.map(|i| i as u32), f, w, p - anchor, core);
        }
        e
    }

    fn push(&mut self, nodes: [u32; 3], face: u32, w: [f64; 3], world: Vec3, core: &[Vec3]) {
        let [a, b, c] = nodes.map(|k| core[k as usize]);
        // A degenerate rest face keeps the world-frame offset (never turned).
        let local = frame(&a, &b, &c).map_or(world, |r| r.transpose() * world);
        self.nodes.push(nodes);
        self.face.push(face);
        self.weights.push(w);
        self.offset.push(local);
        self.rest_offset.push(world);
    }

    /// Ties with given faces, weights and rest (world-frame) offsets to the faces of `core` at
    /// rest (the skin of a [`crate::hybrid::HybridModel`]).
    pub fn from_parts(core: &[Vec3], faces: &[[usize; 3]], face_of: &[u32], weights: &[[f64; 3]], offset: &[Vec3]) -> Embedding {
        let mut e = Embedding::default();
        for ((&f, &w), &o) in face_of.iter().zip(weights).zip(offset) {
            e.push(faces[f as usize].map(|i| i as u32), f, w, o, core);
        }
        e
    }

    /// Number of tied points.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// No tied points?
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Per face of `n_faces`: the largest `sum |w|` and the largest offset length \[m\] of the
    /// points tied to it (zeros for a face without points). A point's place moves by at most
    /// `sum |w| max_a |dx_a| + |dR|_F |o|` when its face's nodes move by `dx_a` and its frame by
    /// `dR` (`position_framed`), so these bound how far a face's points moved.
    pub fn face_reach(&self, n_faces: usize) -> Vec<(f64, f64)> {
        let mut out = vec![(0.0f64, 0.0f64); n_faces];
        for i in 0..self.len() {
            if let Some(b) = out.get_mut(self.face[i] as usize) {
                b.0 = b.0.max(self.weights[i].iter().map(|w| w.abs()).sum());
                b.1 = b.1.max(self.offset[i].norm());
            }
        }
        out
    }

    /// The face nodes and weights of point `i`.
    #[inline]
    pub fn tie(&self, i: usize) -> ([u32; 3], [f64; 3]) {
        (self.nodes[i], self.weights[i])
    }

    /// Position of point `i` for core positions `x` \[m\].
    #[inline]
    pub fn position(&self, i: usize, x: &[Vec3]) -> Vec3 {
        let n = self.nodes[i];
        let [a, b, c] = n.map(|k| &x[k as usize]);
        let turned = frame(a, b, c).map_or(self.rest_offset[i], |r| r * self.offset[i]);
        self.interpolate(i, x) + turned
    }

    /// [`Self::position`] with the face frames given (`frames`, from [`face_frames`] at the same
    /// `x` over the faces the embedding was made with): one frame per face instead of per point.
    #[inline]
    pub fn position_framed(&self, i: usize, x: &[Vec3], frames: &[Option<Mat3>]) -> Vec3 {
        let turned = frames[self.face[i] as usize].map_or(self.rest_offset[i], |r| r * self.offset[i]);
        self.interpolate(i, x) + turned
    }

    /// Velocity of point `i` for core positions `x` and velocities `v` \[m/s\]: the weighted face
    /// velocity plus the turning offset's (`dR/dt o`).
    #[inline]
    pub fn velocity(&self, i: usize, x: &[Vec3], v: &[Vec3]) -> Vec3 {
        let n = self.nodes[i];
        let [a, b, c] = n.map(|k| x[k as usize]);
        let [va, vb, vc] = n.map(|k| v[k as usize]);
        let base = self.interpolate(i, v);
        frame_rate(&a, &b, &c, &va, &vb, &vc).map_or(base, |r| base + r * self.offset[i])
    }

    /// [`Self::velocity`] with the face frames' rates given (`rates`, from
    /// [`face_frames_and_rates`] at the same `x` and `v`).
    #[inline]
    pub fn velocity_framed(&self, i: usize, v: &[Vec3], rates: &[Mat3]) -> Vec3 {
        self.interpolate(i, v) + rates[self.face[i] as usize] * self.offset[i]
    }

    /// The weighted face value at point `i` (a velocity, a displacement) of a core field `u`.
    #[inline]
    pub fn interpolate(&self, i: usize, u: &[Vec3]) -> Vec3 {
        let (n, w) = (self.nodes[i], self.weights[i]);
        w[0] * u[n[0] as usize] + w[1] * u[n[1] as usize] + w[2] * u[n[2] as usize]
    }

    /// Adds a force `f` on point `i` to the core forces `out`, for core positions `x`: the exact
    /// transpose of [`Self::position`] (virtual work), whose shares sum to `f`.
    #[inline]
    pub fn spread(&self, i: usize, f: Vec3, x: &[Vec3], out: &mut [Vec3]) {
        let (n, w) = (self.nodes[i], self.weights[i]);
        let [a, b, c] = n.map(|k| x[k as usize]);
        let (e, g) = (b - a, c - a);
        let m = e.cross(&g);
        let (le, lm) = (e.norm(), m.norm());
        for k in 0..3 {
            out[n[k] as usize] += w[k] * f;
        }
        if !(le > 0.0 && lm > 1e-30 * le * le && lm.is_finite()) {
            return;
        }
        // R o = o1 e1 + o2 e2 + o3 n, with de1 = P1 de / |e|, dn = Pn dm / |m|,
        // dm = de x g + e x dg, de2 = dn x e1 + n x de1 (P: the projector off the unit vector).
        // f . d(R o) = u . de + q . dm, and q . dm = de . (g x q) + dg . (q x e).
        let (e1, nn) = (e / le, m / lm);
        let o = self.offset[i];
        let off1 = |v: Vec3| v - e1 * e1.dot(&v);
        let offn = |v: Vec3| v - nn * nn.dot(&v);
        let u = off1(o.x * f + o.y * f.cross(&nn)) / le;
        let q = offn(o.z * f + o.y * e1.cross(&f)) / lm;
        let gb = u + g.cross(&q);
        let gc = q.cross(&e);
        out[n[0] as usize] -= gb + gc;
        out[n[1] as usize] += gb;
        out[n[2] as usize] += gc;
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

    /// The offsets in their faces' frames \[m\] (their lengths are the points' distances from
    /// their weighted face points).
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
    fn offsets_turn_with_their_face_and_the_velocity_is_the_positions_derivative() {
        let (core, faces) = tri();
        let rest = [Vec3::new(0.2, 0.3, 0.5), Vec3::new(0.6, 0.1, -0.2)];
        let e = Embedding::project(&core, &faces, &[0, 0], &rest);
        // A rigid rotation and translation of the core carries the tied points rigidly.
        let r = nalgebra::Rotation3::from_euler_angles(0.4, -0.2, 0.9);
        let t = Vec3::new(0.1, 0.2, -0.3);
        let moved: Vec<Vec3> = core.iter().map(|x| r * x + t).collect();
        let mut frames = vec![None; faces.len()];
        face_frames(&moved, &faces, &mut frames);
        for (i, p) in rest.iter().enumerate() {
            assert!((e.position(i, &moved) - (r * p + t)).norm() < 1e-13);
            assert_eq!(e.position_framed(i, &moved, &frames), e.position(i, &moved));
        }
        let v: Vec<Vec3> = (0..core.len()).map(|k| Vec3::new(0.1 * k as f64, -0.2, 0.05 * k as f64)).collect();
        let mut rates = vec![Mat3::zeros(); faces.len()];
        face_frames_and_rates(&moved, &v, &faces, &mut frames, &mut rates);
        for i in 0..rest.len() {
            assert!((e.velocity_framed(i, &v, &rates) - e.velocity(i, &moved, &v)).norm() < 1e-15);
        }
        // velocity = d position / dt along a deforming motion (central differences).
        let v: Vec<Vec3> = (0..core.len()).map(|k| Vec3::new(0.3 * k as f64 - 0.2, 0.5 - 0.1 * k as f64, 0.2 * k as f64)).collect();
        let h = 1e-6;
        let at = |s: f64| -> Vec<Vec3> { moved.iter().zip(&v).map(|(x, v)| x + s * v).collect() };
        for i in 0..rest.len() {
            let fd = (e.position(i, &at(h)) - e.position(i, &at(-h))) / (2.0 * h);
            assert!((e.velocity(i, &moved, &v) - fd).norm() < 1e-7, "{i}: {} vs {}", e.velocity(i, &moved, &v), fd);
        }
        // A degenerate face keeps the rest offset: the point stays finite.
        let flat = vec![Vec3::zeros(); core.len()];
        assert!(e.position(0, &flat).iter().all(|c| c.is_finite()));
    }

    #[test]
    fn spreading_is_the_transpose_and_keeps_the_total() {
        let (core, faces) = tri();
        let e = Embedding::project(&core, &faces, &[0], &[Vec3::new(0.25, 0.25, 0.1)]);
        let f = Vec3::new(1.0, -2.0, 0.5);
        // At rest and at a deformed, turned configuration.
        let r = nalgebra::Rotation3::from_euler_angles(0.3, 0.5, -0.4);
        let bent: Vec<Vec3> = core.iter().enumerate().map(|(k, x)| r * x + Vec3::new(0.05 * k as f64, -0.02 * k as f64, 0.1)).collect();
        for x in [&core, &bent] {
            let mut out = vec![Vec3::zeros(); core.len()];
            e.spread(0, f, x, &mut out);
            assert!((out.iter().sum::<Vec3>() - f).norm() < 1e-14);
            // Virtual work: f . dx_p = sum_k out_k . dx_k for any core motion dx (the velocity
            // is the position's derivative, tested above).
            let dx: Vec<Vec3> = (0..core.len()).map(|k| Vec3::new(0.3 * k as f64, -0.1, 0.7 - k as f64)).collect();
            let lhs = f.dot(&e.velocity(0, x, &dx));
            let rhs: f64 = out.iter().zip(&dx).map(|(a, b)| a.dot(b)).sum();
            assert!((lhs - rhs).abs() < 1e-13, "{lhs} vs {rhs}");
        }
    }
}
