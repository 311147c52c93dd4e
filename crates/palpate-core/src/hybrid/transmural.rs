//! The transmural coordinate of an organ wall: a harmonic function `phi` that is 0 on the inner
//! surface and 1 on the outer one (zero flux through a base), solved on a voxel grid of the wall,
//! and the direction field `grad phi / |grad phi|`.
//!
//! The paper projects "in a radial direction towards the object's mass centre", which only works
//! for walls that are star-shaped about that centre. Streamlines of a harmonic function go from
//! the inner to the outer surface without ever turning back (a harmonic function has no interior
//! extremum), whatever the shape; for two concentric spheres they are the radial lines. The
//! radial mode is kept as [`Projection::Radial`].
//!
//! Discretisation: cell-centred voxels of edge `h`; a voxel belongs to the wall when its centre
//! is inside the wall's closed boundary (ray parity along z, exact). The 7-point Laplacian over
//! wall voxels, with the face-neighbours outside the wall set to 0 or 1 (Dirichlet) by the part
//! of the nearest boundary triangle (inner or outer) or dropped (Neumann) when it is a base
//! triangle, is solved by Jacobi-preconditioned conjugate gradients.

use crate::linalg::cg::{self, CgStop, CgWork};
use crate::math::Vec3;
use crate::mesh::surface::TriSurface;
use crate::spatial::{Grid3, Nearest, TriangleGrid};
use std::collections::VecDeque;

/// Which part of a wall's closed boundary a triangle belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum WallPart {
    /// The inner surface (endocardium): `phi = 0`.
    Inner = 0,
    /// The outer surface (epicardium): `phi = 1`.
    Outer = 1,
    /// A base (cut plane, valve ring): no flux; the wall is held there.
    Base = 2,
}

/// How the builder projects between the outer surface and the core.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Projection {
    /// Along the streamlines of the transmural harmonic field (default; any wall shape).
    Transmural,
    /// The paper's: along straight lines through the wall's mass centre (star-shaped walls only).
    Radial,
}

/// A cell-centred voxel grid: voxel `(i, j, k)` has its centre at `origin + (i + 1/2, j + 1/2,
/// k + 1/2) h` (the crate's one uniform grid, [`Grid3`]).
pub type VoxelGrid = Grid3;

/// The wall voxels and the transmural field on them.
#[derive(Debug, Clone)]
pub struct Transmural {
    /// The grid.
    pub grid: VoxelGrid,
    /// Per voxel: inside the wall?
    pub wall: Vec<bool>,
    /// Per voxel: `phi`, extended outside the wall (0 on the inner side, 1 on the outer side,
    /// the nearest wall value beyond a base).
    pub phi: Vec<f64>,
    /// Per voxel: the unit transmural direction (extended outside the wall from the nearest wall
    /// voxel).
    pub dir: Vec<Vec3>,
    /// Conjugate-gradient iterations the solve took, and its final relative residual.
    pub iterations: usize,
    pub residual: f64,
    /// Mass centre of the wall (voxel centroid) \[m\], for the radial mode.
    pub centre: Vec3,
}

/// Build the voxel grid of a wall (closed boundary `surface`, part per triangle) with voxel edge
/// `h` and solve the transmural field.
pub fn solve(surface: &TriSurface, parts: &[WallPart], h: f64, tri_grid: &TriangleGrid) -> Transmural {
    let (lo, hi) = surface.bounding_box();
    let pad = 2.0 * h;
    let origin = lo - Vec3::repeat(pad);
    let ext = hi - lo + Vec3::repeat(2.0 * pad);
    let dims = [(ext.x / h).ceil() as usize, (ext.y / h).ceil() as usize, (ext.z / h).ceil() as usize];
    let grid = VoxelGrid { origin, h, dims };
    let n = grid.len();
    // Inside test by z-columns.
    let mut wall = vec![false; n];
    let mut zs = Vec::new();
    for j in 0..dims[1] {
        for i in 0..dims[0] {
            let x = origin.x + (i as f64 + 0.5) * h;
            let y = origin.y + (j as f64 + 0.5) * h;
            zs.clear();
            surface.column_crossings(x, y, &mut zs);
            zs.sort_by(f64::total_cmp);
            if zs.is_empty() {
                continue;
            }
            let mut c = 0;
            for k in 0..dims[2] {
                let z = origin.z + (k as f64 + 0.5) * h;
                while c < zs.len() && zs[c] < z {
                    c += 1;
                }
                wall[grid.index(i, j, k)] = c % 2 == 1;
            }
        }
    }
    // Boundary values of the exterior voxels that touch the wall.
    let pts = surface.points();
    let tris = surface.triangles();
    // Exterior classification: 0 inner, 1 outer, 2 base (Neumann), 3 not adjacent.
    let mut ext_kind = vec![3u8; n];
    for v in 0..n {
        if !wall[v] {
            continue;
        }
        for w in grid.face_neighbours(v).into_iter().flatten() {
            if !wall[w] && ext_kind[w] == 3 {
                let c = grid.centre(w);
                ext_kind[w] = match tri_grid.nearest(pts, tris, &c, |_| true) {
                    Some(Nearest { triangle, .. }) => parts[triangle] as u8,
                    None => 1,
                };
            }
        }
    }
    // Unknowns.
    let mut id = vec![u32::MAX; n];
    let mut cells = Vec::new();
    for v in 0..n {
        if wall[v] {
            id[v] = cells.len() as u32;
            cells.push(v);
        }
    }
    let m = cells.len();
    let mut diag = vec![0.0; m];
    let mut b = vec![0.0; m];
    for (r, &v) in cells.iter().enumerate() {
        for w in grid.face_neighbours(v).into_iter().flatten() {
            if wall[w] {
                diag[r] += 1.0;
            } else {
                match ext_kind[w] {
                    0 => diag[r] += 1.0,
                    1 => {
                        diag[r] += 1.0;
                        b[r] += 1.0;
                    }
                    _ => {}
                }
            }
        }
        if diag[r] == 0.0 {
            diag[r] = 1.0;
        }
    }
    // Wall neighbours of each unknown, as unknown indices (u32::MAX: none).
    let links: Vec<[u32; 6]> = cells
        .iter()
        .map(|&v| {
            let mut l = [u32::MAX; 6];
            for (k, w) in grid.face_neighbours(v).into_iter().enumerate() {
                if let Some(w) = w {
                    if wall[w] {
                        l[k] = id[w];
                    }
                }
            }
            l
        })
        .collect();
    let apply = |x: &[f64], y: &mut [f64]| {
        for r in 0..m {
            let mut s = diag[r] * x[r];
            for &w in &links[r] {
                if w != u32::MAX {
                    s -= x[w as usize];
                }
            }
            y[r] = s;
        }
    };
    // Initial guess: 1/2 everywhere.
    let mut x = vec![0.5; m];
    let max_iterations = 20 * (m as f64).cbrt() as usize + 500;
    let jacobi = |r: &[f64], z: &mut [f64]| z.iter_mut().zip(r).zip(&diag).for_each(|((z, r), d)| *z = r / d);
    let report = cg::solve(apply, jacobi, &b, &mut x, &mut CgWork::new(m), CgStop { tolerance: 1e-8, max_iterations });
    let (iterations, residual) = (report.iterations, report.residual);
    // Extend phi: exterior voxels by their part, then nearest-wall BFS for the rest.
    let mut phi = vec![f64::NAN; n];
    for (r, &v) in cells.iter().enumerate() {
        phi[v] = x[r].clamp(0.0, 1.0);
    }
    let mut nearest = vec![u32::MAX; n];
    let mut queue = VecDeque::new();
    for &v in &cells {
        nearest[v] = v as u32;
        queue.push_back(v);
    }
    while let Some(v) = queue.pop_front() {
        for w in grid.face_neighbours(v).into_iter().flatten() {
            if nearest[w] == u32::MAX {
                nearest[w] = nearest[v];
                queue.push_back(w);
            }
        }
    }
    for v in 0..n {
        if !wall[v] {
            phi[v] = match ext_kind[v] {
                0 => 0.0,
                1 => 1.0,
                _ => {
                    let w = nearest[v];
                    if w == u32::MAX {
                        0.5
                    } else {
                        phi[w as usize]
                    }
                }
            };
        }
    }
    // Far exterior voxels (not adjacent): inner side if the nearest wall voxel is closer to 0.
    for v in 0..n {
        if !wall[v] && ext_kind[v] == 3 {
            let w = nearest[v];
            phi[v] = if w == u32::MAX {
                1.0
            } else if phi[w as usize] < 0.5 {
                0.0
            } else {
                1.0
            };
        }
    }
    // Direction: central differences at wall voxels, copied outward.
    let mut dir = vec![Vec3::zeros(); n];
    for &v in &cells {
        let c = grid.ijk(v);
        let mut g = Vec3::zeros();
        for a in 0..3 {
            let (mut lo_c, mut hi_c) = (c, c);
            if c[a] > 0 {
                lo_c[a] -= 1;
            }
            if c[a] + 1 < dims[a] {
                hi_c[a] += 1;
            }
            let (vl, vh) = (grid.index(lo_c[0], lo_c[1], lo_c[2]), grid.index(hi_c[0], hi_c[1], hi_c[2]));
            let span = (hi_c[a] - lo_c[a]) as f64 * h;
            if span > 0.0 {
                g[a] = (phi[vh] - phi[vl]) / span;
            }
        }
        dir[v] = if g.norm() > 0.0 { g.normalize() } else { Vec3::zeros() };
    }
    for v in 0..n {
        if !wall[v] && nearest[v] != u32::MAX {
            dir[v] = dir[nearest[v] as usize];
        }
    }
    let mut centre = Vec3::zeros();
    for &v in &cells {
        centre += grid.centre(v);
    }
    centre /= m.max(1) as f64;
    Transmural { grid, wall, phi, dir, iterations, residual, centre }
}

impl Transmural {
    /// Trilinear interpolation weights of `p` over the 8 surrounding voxel centres.
    fn stencil(&self, p: &Vec3) -> [(usize, f64); 8] {
        let g = &self.grid;
        let mut base = [0usize; 3];
        let mut f = [0.0; 3];
        for a in 0..3 {
            let x = ((p[a] - g.origin[a]) / g.h - 0.5).clamp(0.0, (g.dims[a] - 1) as f64 - 1e-9);
            base[a] = (x.floor() as usize).min(g.dims[a].saturating_sub(2));
            f[a] = x - base[a] as f64;
        }
        let mut out = [(0usize, 0.0); 8];
        for (m, o) in out.iter_mut().enumerate() {
            let (di, dj, dk) = (m & 1, (m >> 1) & 1, (m >> 2) & 1);
            let w = (if di == 1 { f[0] } else { 1.0 - f[0] }) * (if dj == 1 { f[1] } else { 1.0 - f[1] }) * (if dk == 1 { f[2] } else { 1.0 - f[2] });
            let (i, j, k) = ((base[0] + di).min(g.dims[0] - 1), (base[1] + dj).min(g.dims[1] - 1), (base[2] + dk).min(g.dims[2] - 1));
            *o = (g.index(i, j, k), w);
        }
        out
    }

    /// `phi` at `p` (trilinear).
    pub fn phi_at(&self, p: &Vec3) -> f64 {
        self.stencil(p).iter().map(|&(v, w)| w * self.phi[v]).sum()
    }

    /// Unit transmural direction (inner to outer) at `p`.
    pub fn dir_at(&self, p: &Vec3, mode: Projection) -> Vec3 {
        match mode {
            Projection::Radial => {
                let d = p - self.centre;
                if d.norm() > 0.0 {
                    d.normalize()
                } else {
                    Vec3::z()
                }
            }
            Projection::Transmural => {
                let d: Vec3 = self.stencil(p).iter().map(|&(v, w)| w * self.dir[v]).sum();
                if d.norm() > 0.0 {
                    d.normalize()
                } else {
                    Vec3::zeros()
                }
            }
        }
    }

    /// Is `p` in a wall voxel?
    pub fn in_wall(&self, p: &Vec3) -> bool {
        self.grid.cell_of(p).is_some_and(|c| self.wall[self.grid.index_of(c)])
    }

    /// March from `p` along the direction field (`outward`: towards the outer surface) until
    /// `phi` reaches `level` (crossing it from the start side). Returns the end point, or `None`
    /// if the path leaves the grid, stalls or turns back (the mode cannot serve there).
    pub fn march_to_level(&self, p: &Vec3, level: f64, outward: bool, mode: Projection) -> Option<Vec3> {
        let step = 0.75 * self.grid.h;
        let sign = if outward { 1.0 } else { -1.0 };
        let mut x = *p;
        let mut f = self.phi_at(&x);
        let reached = |f: f64| if outward { f >= level } else { f <= level };
        if reached(f) {
            return Some(x);
        }
        let g = &self.grid;
        let diag = (g.dims[0] * g.dims[0] + g.dims[1] * g.dims[1] + g.dims[2] * g.dims[2]) as f64;
        let max_steps = (4.0 * diag.sqrt()) as usize + 16;
        let mut stalled = 0;
        for _ in 0..max_steps {
            let d1 = self.dir_at(&x, mode);
            if d1.norm() == 0.0 {
                return None;
            }
            let mid = x + 0.5 * step * sign * d1;
            let d2 = self.dir_at(&mid, mode);
            let d = if d2.norm() > 0.0 { d2 } else { d1 };
            let y = x + step * sign * d;
            g.cell_of(&y)?;
            let fy = self.phi_at(&y);
            if reached(fy) {
                // Linear interpolation of the crossing.
                let t = if (fy - f).abs() > 0.0 { ((level - f) / (fy - f)).clamp(0.0, 1.0) } else { 1.0 };
                return Some(x + t * (y - x));
            }
            // Progress check: phi must move the right way (radial lines may turn back).
            if (fy - f) * sign <= 0.0 {
                stalled += 1;
                if stalled > 8 {
                    return None;
                }
            } else {
                stalled = 0;
            }
            x = y;
            f = fy;
        }
        None
    }
}
