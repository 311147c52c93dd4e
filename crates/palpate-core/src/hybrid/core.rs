//! The FEM core Omega_e (paper §4): the inner surface simplified (quadric edge collapse), lifted
//! into the wall, offset along the transmural field to phi = f (the core fraction) in L layers,
//! each prism split into 3 tets; and its section of the model file.

use super::file::{finite, in_range, Reader, Res, Writer};
use super::model::HybridModel;
use super::options::{AUTO_CORE_TRIANGLES_BASE, AUTO_CORE_TRIANGLES_CLOSED};
use super::transmural::{Projection, Transmural, WallPart};
use super::wall::Wall;
use crate::error::HybridError;
use crate::math::Vec3;
use crate::mesh::prism::{split_prism, TetOrder};
use crate::mesh::simplify::{simplify, Simplified};
use crate::mesh::{signed_volume, TetMesh, TriSurface};
use crate::spatial::{Nearest, TriangleGrid};

/// Quality of the FEM core.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CoreQuality {
    /// Smallest dihedral angle \[deg\].
    pub min_dihedral_deg: f64,
    /// Smallest and largest tet volume \[m^3\].
    pub min_volume: f64,
    pub max_volume: f64,
}

/// The core's prism layers when [`super::HybridOptions::core_layers`] is 0: its mean height over
/// the mean edge of its triangles, rounded (1 to [`MAX_AUTO_CORE_LAYERS`]), so that its tets are
/// about as tall as wide. One layer of prisms much taller than wide is far stiffer than the tissue
/// under a local load: on the 40 mm slab of VALIDATION.md (a 34 mm core under 300 triangles about
/// 7 mm wide), a 15 mm sphere met +50 / +31 / +19% of Hertz's force at 1.4 / 3.1 / 4.1 mm with one
/// layer and +28 / +11 / 0% with five. The ventricles' cores are thinner than wide: one layer.
fn auto_layers(points: &[Vec3], tris: &[[usize; 3]], top: impl Fn(usize) -> Vec3) -> usize {
    let edge = tris.iter().map(|t| (0..3).map(|k| (points[t[k]] - points[t[(k + 1) % 3]]).norm()).sum::<f64>() / 3.0).sum::<f64>() / tris.len().max(1) as f64;
    let height = (0..points.len()).map(|v| (top(v) - points[v]).norm()).sum::<f64>() / points.len().max(1) as f64;
    let n = (height / edge).round();
    if n.is_finite() {
        (n as usize).clamp(1, MAX_AUTO_CORE_LAYERS)
    } else {
        1
    }
}

/// The most layers [`auto_layers`] gives (300 triangles: 7,200 tets).
pub const MAX_AUTO_CORE_LAYERS: usize = 8;

/// The core of `wall` with [`super::HybridOptions::core_triangles`] coarse triangles, or, when that is
/// 0, the automatic count raised by half (up to twice) while a prism stays twisted: the core
/// fields of `m` (from `m.options`).
pub(super) fn build(m: &mut HybridModel, wall: &Wall, field: &Transmural, wall_grid: &TriangleGrid) -> Result<(), HybridError> {
    let o = m.options;
    let closed = !wall.parts.contains(&WallPart::Base);
    let (mut n_tri, mut tries) = match o.core_triangles {
        0 => (if closed { AUTO_CORE_TRIANGLES_CLOSED } else { AUTO_CORE_TRIANGLES_BASE }, 3),
        n => (n, 1),
    };
    loop {
        match build_with(m, wall, field, wall_grid, n_tri) {
            Err(HybridError::TwistedCore { .. }) if tries > 1 => {
                tries -= 1;
                n_tri += n_tri / 2;
            }
            result => return result,
        }
    }
}

/// The FEM core: the inner surface simplified to `n_tri` triangles, lifted into the wall,
/// offset in layers along the field and split into tets (`m` is changed only on success).
fn build_with(m: &mut HybridModel, wall: &Wall, field: &Transmural, wall_grid: &TriangleGrid, n_tri: usize) -> Result<(), HybridError> {
    let o = &m.options;
    let surf = &wall.surface;
    let inner = wall.part(WallPart::Inner);
    let mut coarse = simplify(&inner.points, &inner.tris, n_tri);
    balance_on_surface(&mut coarse, surf, &wall.parts, wall_grid, field, 0.95 * o.core_fraction);
    if coarse.triangles.len() < 4 {
        return Err(HybridError::Core(format!("the inner surface simplified to {} triangles", coarse.triangles.len())));
    }
    let nv = coarse.points.len();
    // Layer l of vertex v sits at phi_b + l/L (f - phi_b), phi_b the level of the (lifted)
    // inner vertex; at least a quarter of the core fraction above it, so that no prism is flat.
    // Vertices on a boundary loop (a base or valve ring) go straight towards the nearest point of
    // the outer surface instead, across the ring: the field is degenerate along the rim.
    let phi_b: Vec<f64> = coarse.points.iter().map(|p| field.phi_at(p)).collect();
    let outer_dir: Vec<Vec3> = coarse
        .points
        .iter()
        .map(|p| match wall_grid.nearest(surf.points(), surf.triangles(), p, |t| wall.parts[t] == WallPart::Outer) {
            Some(n) => n.point - p,
            None => Vec3::zeros(),
        })
        .collect();
    // Vertex v lifted to the fraction `frac` of the core's height.
    let place = |v: usize, frac: f64| -> Vec3 {
        let p = &coarse.points[v];
        let straight = p + o.core_fraction * frac * outer_dir[v];
        if coarse.boundary[v] || phi_b[v] >= 0.95 {
            return straight;
        }
        let span = (o.core_fraction - phi_b[v]).max(0.25 * o.core_fraction);
        let level = (phi_b[v] + span * frac).min(0.95);
        field
            .march_to_level(p, level, true, o.projection)
            .or_else(|| field.march_to_level(p, level, true, Projection::Transmural))
            .unwrap_or(straight)
    };
    let layers = match o.core_layers {
        0 => auto_layers(&coarse.points, &coarse.triangles, |v| place(v, 1.0)),
        n => n,
    };
    let mut core_points = Vec::with_capacity(nv * (layers + 1));
    core_points.extend(coarse.points.iter().copied());
    for l in 1..=layers {
        let frac = l as f64 / layers as f64;
        core_points.extend((0..nv).map(|v| place(v, frac)));
    }
    // Prisms: the inner triangles face the cavity and the layers rise into the wall, so every
    // tet of a sound prism has negative signed volume as split. A twisted prism (offsets of
    // neighbouring vertices pointing apart, e.g. along a valve ring) shows a tet of the other
    // sign; the offsets of its vertices are then smoothed towards their neighbours' until none
    // is left.
    let prisms: Vec<[usize; 4]> = (0..layers)
        .flat_map(|l| coarse.triangles.iter().flat_map(move |tri| split_prism(tri.map(|v| v + l * nv), nv, TetOrder::Rotated)))
        .collect();
    untangle(&mut core_points, &prisms, &coarse.triangles, nv, layers);
    let mut core_tets = Vec::with_capacity(prisms.len());
    for (t, tet) in prisms.iter().enumerate() {
        let v = tet_vol(&core_points, tet);
        if !(v < 0.0) {
            return Err(HybridError::TwistedCore { prism: t / 3, triangle: (t / 3) % coarse.triangles.len(), radial: o.projection == Projection::Radial });
        }
        core_tets.push([tet[0], tet[2], tet[1], tet[3]]);
    }
    let core_faces: Vec<[usize; 3]> = coarse
        .triangles
        .iter()
        .map(|t| {
            // The inner triangles face the cavity; the top faces face the shell.
            let o = layers * nv;
            [t[0] + o, t[2] + o, t[1] + o]
        })
        .collect();
    let pts_arr: Vec<[f64; 3]> = core_points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tets_arr: Vec<[i64; 4]> = core_tets.iter().map(|t| [t[0] as i64, t[1] as i64, t[2] as i64, t[3] as i64]).collect();
    let (mesh, warnings) = TetMesh::from_arrays(&pts_arr, &tets_arr).map_err(HybridError::Mesh)?;
    if let Some(w) = warnings.first() {
        return Err(HybridError::Core(format!("{w:?} (try fewer core triangles, more layers or a larger core fraction)")));
    }
    let vols: Vec<f64> = core_tets.iter().map(|t| tet_vol(&core_points, t)).collect();
    m.core_quality = CoreQuality {
        min_dihedral_deg: mesh.min_dihedral_deg(),
        min_volume: vols.iter().copied().fold(f64::INFINITY, f64::min),
        max_volume: vols.iter().copied().fold(0.0, f64::max),
    };
    let mut core_base_nodes: Vec<usize> = Vec::new();
    for (v, &b) in coarse.boundary.iter().enumerate() {
        if b {
            for l in 0..=layers {
                core_base_nodes.push(v + l * nv);
            }
        }
    }
    core_base_nodes.sort_unstable();
    m.core_base_nodes = core_base_nodes;
    // The layers as built (an automatic count resolved): the model file says what it holds.
    m.options.core_layers = layers;
    m.core_points = core_points;
    m.core_tets = core_tets;
    m.core_faces = core_faces;
    Ok(())
}

fn tet_vol(pts: &[Vec3], t: &[usize; 4]) -> f64 {
    signed_volume(&pts[t[0]], &pts[t[1]], &pts[t[2]], &pts[t[3]])
}

/// Smooth the layer offsets of the vertices of twisted prisms (a tet of non-negative signed
/// volume as split) and of their neighbours towards their neighbours' until none is left (at
/// most 200 rounds).
fn untangle(core_points: &mut [Vec3], prisms: &[[usize; 4]], triangles: &[[usize; 3]], nv: usize, layers: usize) {
    let mut vnbrs: Vec<Vec<usize>> = vec![vec![]; nv];
    for tri in triangles {
        for k in 0..3 {
            vnbrs[tri[k]].push(tri[(k + 1) % 3]);
            vnbrs[tri[k]].push(tri[(k + 2) % 3]);
        }
    }
    vnbrs.iter_mut().for_each(|v| {
        v.sort_unstable();
        v.dedup();
    });
    let mut untangle_rounds = 0;
    loop {
        let scale = core_points
            .iter()
            .take(nv)
            .zip(core_points.iter().skip(layers * nv))
            .map(|(a, b)| (b - a).norm())
            .fold(0.0, f64::max)
            .max(1e-9);
        let bad: Vec<usize> = prisms
            .iter()
            .filter(|t| tet_vol(core_points, t) > -1e-6 * scale.powi(3))
            .flat_map(|t| t.iter().map(|&n| n % nv))
            .collect();
        if bad.is_empty() || untangle_rounds >= 200 {
            break;
        }
        untangle_rounds += 1;
        let mut mark = vec![false; nv];
        for &v in &bad {
            mark[v] = true;
            for &w in &vnbrs[v] {
                mark[w] = true;
            }
        }
        for l in 1..=layers {
            let off: Vec<Vec3> = (0..nv).map(|v| core_points[v + l * nv] - core_points[v]).collect();
            for v in 0..nv {
                if mark[v] && !vnbrs[v].is_empty() {
                    let mean: Vec3 = vnbrs[v].iter().map(|&w| off[w]).sum::<Vec3>() / vnbrs[v].len() as f64;
                    core_points[v + l * nv] = core_points[v] + 0.5 * (off[v] + mean);
                }
            }
        }
    }
}

/// Move the vertices of the coarse inner surface along the transmural direction until the
/// coarse surface lies in the wall: chords of a curved surface cut into the cavity, and the core
/// would otherwise take cavity volume (the wall region this leaves between the coarse and the
/// true inner surface is filled with particles). The signed depth of a sample point is its
/// distance to the nearest inner triangle, negative on the cavity side; each vertex rises by the
/// deepest cavity-side depth among the samples of its triangles it weighs most in. Boundary
/// (base) vertices stay.
fn balance_on_surface(coarse: &mut Simplified, surf: &TriSurface, parts: &[WallPart], grid: &TriangleGrid, field: &Transmural, max_level: f64) {
    let (pts, tris) = (surf.points(), surf.triangles());
    const K: usize = 6;
    for _ in 0..4 {
        let mut lift = vec![0.0f64; coarse.points.len()];
        for tri in &coarse.triangles {
            let (a, b, c) = (coarse.points[tri[0]], coarse.points[tri[1]], coarse.points[tri[2]]);
            for i in 0..=K {
                for j in 0..=K - i {
                    let w = [(K - i - j) as f64 / K as f64, i as f64 / K as f64, j as f64 / K as f64];
                    let p = w[0] * a + w[1] * b + w[2] * c;
                    let Some(Nearest { triangle: t, point: q, distance: d, .. }) = grid.nearest(pts, tris, &p, |t| parts[t] == WallPart::Inner) else {
                        continue;
                    };
                    let f = tris[t];
                    let n = (pts[f[1]] - pts[f[0]]).cross(&(pts[f[2]] - pts[f[0]]));
                    if (p - q).dot(&n) <= 0.0 {
                        continue; // in the wall
                    }
                    // The vertex this sample weighs most on rises by its depth.
                    let k = (0..3).max_by(|&x, &y| w[x].total_cmp(&w[y])).unwrap();
                    lift[tri[k]] = lift[tri[k]].max(d);
                }
            }
        }
        let mut moved = false;
        for v in 0..coarse.points.len() {
            if coarse.boundary[v] || lift[v] == 0.0 {
                continue;
            }
            // In small steps, and never past 0.95 of the core fraction in phi (a sample
            // far from the inner surface, e.g. across a valve opening, must not push the vertex
            // through the wall).
            let steps = (lift[v] / (0.25 * field.grid.h)).ceil().max(1.0) as usize;
            let dl = lift[v] / steps as f64;
            for _ in 0..steps {
                let p = coarse.points[v];
                let q = p + dl * field.dir_at(&p, Projection::Transmural);
                if field.phi_at(&q) > max_level {
                    break;
                }
                coarse.points[v] = q;
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
}

pub(super) fn write(m: &HybridModel, w: &mut Writer) {
    w.vec3s(&m.core_points);
    w.idx(&m.core_tets);
    w.idx(&m.core_faces);
    w.usizes(&m.core_base_nodes);
    let q = &m.core_quality;
    w.f64(q.min_dihedral_deg);
    w.f64(q.min_volume);
    w.f64(q.max_volume);
}

// A model file is input from anywhere: its section reader may not panic (as file.rs).
#[deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub(super) fn read(r: &mut Reader, m: &mut HybridModel) -> Res<()> {
    m.core_points = r.vec3s("core points")?;
    m.core_tets = r.idx::<4>("core tets")?;
    m.core_faces = r.idx::<3>("core faces")?;
    m.core_base_nodes = r.usizes("core base nodes")?;
    m.core_quality = CoreQuality { min_dihedral_deg: r.f64("core quality")?, min_volume: r.f64("core quality")?, max_volume: r.f64("core quality")? };
    Ok(())
}

pub(super) fn check(m: &HybridModel) -> Result<(), String> {
    let nc = m.core_points.len();
    in_range("core tets", m.core_tets.iter().flatten().copied(), nc)?;
    in_range("core faces", m.core_faces.iter().flatten().copied(), nc)?;
    in_range("core base nodes", m.core_base_nodes.iter().copied(), nc)?;
    finite("core points", &m.core_points)
}
