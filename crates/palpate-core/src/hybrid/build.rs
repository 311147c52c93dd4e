//! Building the hybrid model (paper §4 and §6) from the surfaces of an organ wall.
//!
//! ```text
//! wall boundary (closed, parts inner/outer/base)
//!   ├─ transmural field phi on wall voxels ............................ transmural.rs
//!   ├─ FEM core Omega_e: inner surface simplified (quadric collapse), offset along the field
//!   │  to phi = f (the core fraction) in L layers; prisms split into 3 tets each, consistently
//!   ├─ particles Omega_p: lattice points inside the wall and outside the core
//!   ├─ per particle: the outer triangle above it and the core face below it (field lines)
//!   ├─ per outer vertex p_s: nv(p_s) (its triangles, grown by rings until enough particles),
//!   │  RV(p_s) (the particles under those triangles), C(p_s) (the projections of nv's
//!   │  boundary onto the core), the core faces under RV, and the box B(p_s) in the shared voxels
//!   └─ skin: each outer vertex tied to the core face its projection hits (barycentric, offset)
//! ```

use super::geometry::{TetGrid, TriangleGrid};
use super::transmural::{self, Projection, Transmural, VoxelGrid, WallPart};
use crate::error::HybridError;
use crate::math::Vec3;
use crate::mesh::simplify::simplify;
use crate::mesh::{sample_inside, signed_volume, TetMesh, TriSurface};
use std::collections::HashMap;
use std::time::Instant;

/// Particle spacing: a length, or the number of particles the shell should hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Spacing {
    /// Lattice spacing \[m\].
    Length(f64),
    /// About this many particles in the shell (the paper's ventricle has 27,988).
    Count(usize),
}

/// Options of [`build`]. `Default` gives the paper's layout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HybridOptions {
    /// Projection between the outer surface and the core.
    pub projection: Projection,
    /// Fraction of the wall thickness (in the transmural coordinate) that the FEM core takes,
    /// from the inner surface \[-\], in (0, 1).
    pub core_fraction: f64,
    /// Triangles of the simplified inner surface (each becomes `3 * core_layers` tets); 0:
    /// automatic, [`AUTO_CORE_TRIANGLES_CLOSED`] for a closed wall and
    /// [`AUTO_CORE_TRIANGLES_BASE`] for one with a base, raised by half (up to twice) while the
    /// core cannot be built without twisted prisms.
    pub core_triangles: usize,
    /// Prism layers of the core.
    pub core_layers: usize,
    /// Particle spacing.
    pub spacing: Spacing,
    /// Density of the wall \[kg/m^3\] (particle masses).
    pub density: f64,
    /// Fewest particles an activation region should hold: nv(p_s) grows by rings of triangles
    /// until RV(p_s) has at least this many (or [`MAX_RINGS`] rings).
    pub min_region_particles: usize,
    /// Wall voxels of the transmural solve (sets the voxel edge).
    pub field_voxels: usize,
}

/// Automatic core resolution of a closed wall (the paper's ellipsoids: 192 tets).
pub const AUTO_CORE_TRIANGLES_CLOSED: usize = 64;
/// Automatic core resolution of a wall with a base (valve rings and cut planes need more).
pub const AUTO_CORE_TRIANGLES_BASE: usize = 300;

/// Rings nv(p_s) may grow to.
pub const MAX_RINGS: usize = 12;

impl Default for HybridOptions {
    fn default() -> Self {
        HybridOptions {
            projection: Projection::Transmural,
            core_fraction: 0.5,
            core_triangles: 0,
            core_layers: 1,
            spacing: Spacing::Count(28_000),
            density: 1000.0,
            min_region_particles: 50,
            field_voxels: 120_000,
        }
    }
}

/// Quality of the FEM core.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreQuality {
    /// Smallest dihedral angle \[deg\].
    pub min_dihedral_deg: f64,
    /// Smallest and largest tet volume \[m^3\].
    pub min_volume: f64,
    pub max_volume: f64,
}

/// Where the build spent its time \[s\] and how the projections went.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BuildStats {
    pub field_s: f64,
    pub core_s: f64,
    pub particles_s: f64,
    pub regions_s: f64,
    pub total_s: f64,
    /// Conjugate-gradient iterations of the transmural solve.
    pub field_iterations: usize,
    /// Projections that could not follow the chosen mode and fell back to the nearest point
    /// (radial lines that leave and re-enter the wall, field lines that exit through a base):
    /// particles to the outer surface, particles to the core, outer vertices to the core.
    pub fallback_particle_outer: usize,
    pub fallback_particle_core: usize,
    pub fallback_skin: usize,
}

/// The compiled hybrid model: the FEM core, the particle shell, the skin and the activation
/// regions. Positions in metres, world frame of the input surfaces.
#[derive(Debug, Clone, PartialEq)]
pub struct HybridModel {
    pub options: HybridOptions,
    /// Volume enclosed by the wall's boundary \[m^3\].
    pub wall_volume: f64,
    // --- FEM core (Omega_e) ---
    pub core_points: Vec<Vec3>,
    pub core_tets: Vec<[usize; 4]>,
    /// Outer boundary faces of the core (towards the shell), oriented outward: where particles
    /// and skin attach.
    pub core_faces: Vec<[usize; 3]>,
    /// Core nodes on a base (held fixed), empty for a closed wall.
    pub core_base_nodes: Vec<usize>,
    pub core_quality: CoreQuality,
    // --- particles (Omega_p), sorted by the outer triangle above them ---
    /// Lattice spacing \[m\].
    pub spacing: f64,
    pub particles: Vec<Vec3>,
    pub particle_mass: Vec<f64>,
    /// Outer triangle above each particle, core face below it.
    pub particle_outer_tri: Vec<u32>,
    pub particle_core_face: Vec<u32>,
    /// Particles of outer triangle `t`: `tri_particle_ptr[t]..tri_particle_ptr[t+1]`.
    pub tri_particle_ptr: Vec<u32>,
    // --- outer surface ---
    pub outer_points: Vec<Vec3>,
    pub outer_tris: Vec<[usize; 3]>,
    // --- activation regions, one per outer vertex ---
    /// nv(p_s) is the outer triangles within `region_rings[s]` rings of vertex `s` (1: the
    /// triangles around it). RV(p_s), C(p_s) and the core faces under RV follow from it (see
    /// [`HybridModel::region_triangles`]): one byte per region is stored.
    pub region_rings: Vec<u8>,
    /// Outer-surface adjacency (derived from `outer_tris`, not stored in the file).
    pub outer_adjacency: OuterAdjacency,
    /// B(p_s): voxel index box `[i0, j0, k0, i1, j1, k1)` in the shared voxel grid.
    pub region_box: Vec<[u32; 6]>,
    // --- skin ---
    /// Per outer vertex: the core face its projection hits, barycentric coordinates on it and
    /// the rest offset from that anchor point to the vertex \[m\].
    pub skin_face: Vec<u32>,
    pub skin_bary: Vec<[f64; 3]>,
    pub skin_offset: Vec<Vec3>,
    // --- shared voxels ---
    pub grid: VoxelGrid,
    /// Per voxel: the outer triangle its field line reaches, or [`VOXEL_OUTSIDE`] /
    /// [`VOXEL_CORE`].
    pub voxel_owner: Vec<u32>,
    pub stats: BuildStats,
}

/// `voxel_owner` of a voxel outside the wall.
pub const VOXEL_OUTSIDE: u32 = u32::MAX;
/// `voxel_owner` of a wall voxel inside the FEM core.
pub const VOXEL_CORE: u32 = u32::MAX - 1;

/// The input: the wall's closed boundary with a part per triangle.
#[derive(Debug, Clone)]
pub struct Wall {
    pub surface: TriSurface,
    pub parts: Vec<WallPart>,
    /// Tiny closed pieces dropped from a tagged surface.
    pub dropped_pieces: usize,
}

/// Smallest volume of a closed piece of a tagged wall surface, relative to the largest piece.
pub const MIN_PIECE_VOLUME: f64 = 1e-3;

/// Split a closed surface into edge-connected pieces and keep those enclosing at least
/// [`MIN_PIECE_VOLUME`] of the largest.
fn drop_specks(surface: TriSurface, parts: Vec<WallPart>) -> Result<(TriSurface, Vec<WallPart>, usize), HybridError> {
    let tris = surface.triangles();
    let n = surface.n_vertices();
    // Union-find over vertices through triangles.
    let mut up: Vec<usize> = (0..n).collect();
    fn find(up: &mut [usize], mut x: usize) -> usize {
        while up[x] != x {
            up[x] = up[up[x]];
            x = up[x];
        }
        x
    }
    for t in tris {
        let a = find(&mut up, t[0]);
        for &v in &t[1..] {
            let b = find(&mut up, v);
            up[b] = a;
        }
    }
    let pts = surface.points();
    let mut vol: HashMap<usize, f64> = HashMap::new();
    for t in tris {
        let r = find(&mut up, t[0]);
        *vol.entry(r).or_insert(0.0) += pts[t[0]].dot(&pts[t[1]].cross(&pts[t[2]])) / 6.0;
    }
    if vol.len() == 1 {
        return Ok((surface, parts, 0));
    }
    let largest = vol.values().copied().fold(0.0, f64::max);
    let keep: Vec<bool> = tris.iter().map(|t| vol[&find(&mut up, t[0])] >= MIN_PIECE_VOLUME * largest).collect();
    let dropped = vol.values().filter(|&&v| v < MIN_PIECE_VOLUME * largest).count();
    let arr: Vec<[f64; 3]> = pts.iter().map(|p| [p.x, p.y, p.z]).collect();
    let mut used = vec![false; n];
    let kept: Vec<usize> = (0..tris.len()).filter(|&t| keep[t]).collect();
    kept.iter().for_each(|&t| tris[t].iter().for_each(|&v| used[v] = true));
    let mut map = vec![0i64; n];
    let mut new_pts = Vec::new();
    for v in 0..n {
        if used[v] {
            map[v] = new_pts.len() as i64;
            new_pts.push(arr[v]);
        }
    }
    let new_tris: Vec<[i64; 3]> = kept.iter().map(|&t| [map[tris[t][0]], map[tris[t][1]], map[tris[t][2]]]).collect();
    let new_parts: Vec<WallPart> = kept.iter().map(|&t| parts[t]).collect();
    let (s, _) = TriSurface::from_arrays(&new_pts, &new_tris)?;
    Ok((s, new_parts, dropped))
}

impl Wall {
    /// Two nested closed surfaces: the wall is the region inside `outer` and outside `inner`.
    pub fn nested(inner: &TriSurface, outer: &TriSurface) -> Result<Wall, HybridError> {
        for (v, p) in inner.points().iter().enumerate() {
            if !outer.contains_parity(p) {
                return Err(crate::mesh::SurfaceError::NotNested { vertex: v, x: p.x, y: p.y, z: p.z }.into());
            }
        }
        if outer.volume() <= inner.volume() {
            return Err(HybridError::Parts(format!("the inner surface encloses {:e} m^3, not less than the outer's {:e} m^3", inner.volume(), outer.volume())));
        }
        let n = outer.n_vertices();
        let mut pts: Vec<[f64; 3]> = outer.points().iter().map(|p| [p.x, p.y, p.z]).collect();
        pts.extend(inner.points().iter().map(|p| [p.x, p.y, p.z]));
        let mut tris: Vec<[i64; 3]> = outer.triangles().iter().map(|t| [t[0] as i64, t[1] as i64, t[2] as i64]).collect();
        // Inner triangles flipped: the wall's boundary faces away from the wall.
        tris.extend(inner.triangles().iter().map(|t| [(t[0] + n) as i64, (t[2] + n) as i64, (t[1] + n) as i64]));
        let mut parts = vec![WallPart::Outer; outer.n_triangles()];
        parts.extend(std::iter::repeat_n(WallPart::Inner, inner.n_triangles()));
        let (surface, _) = TriSurface::from_arrays(&pts, &tris)?;
        Ok(Wall { surface, parts, dropped_pieces: 0 })
    }

    /// One closed surface with a part per triangle (a truncated ventricle: inner, outer, base).
    /// Closed pieces enclosing less than [`MIN_PIECE_VOLUME`] of the largest (specks left by a
    /// surface repair) are dropped; [`Wall::dropped_pieces`] counts them.
    pub fn tagged(surface: TriSurface, parts: Vec<WallPart>) -> Result<Wall, HybridError> {
        if parts.len() != surface.n_triangles() {
            return Err(HybridError::Parts(format!("{} part tags for {} triangles", parts.len(), surface.n_triangles())));
        }
        let (surface, parts, dropped) = drop_specks(surface, parts)?;
        for need in [WallPart::Inner, WallPart::Outer] {
            if !parts.contains(&need) {
                return Err(HybridError::Parts(format!("no {need:?} triangles")));
            }
        }
        Ok(Wall { surface, parts, dropped_pieces: dropped })
    }

    /// The triangles of one part as a surface of its own: `(points, triangles, original vertex
    /// of each point)`.
    fn part(&self, which: WallPart) -> (Vec<Vec3>, Vec<[usize; 3]>, Vec<usize>) {
        let mut map = HashMap::new();
        let (mut pts, mut tris, mut orig) = (vec![], vec![], vec![]);
        for (t, tri) in self.surface.triangles().iter().enumerate() {
            if self.parts[t] != which {
                continue;
            }
            let mut nt = [0; 3];
            for (k, &v) in tri.iter().enumerate() {
                nt[k] = *map.entry(v).or_insert_with(|| {
                    pts.push(self.surface.points()[v]);
                    orig.push(v);
                    pts.len() - 1
                });
            }
            tris.push(nt);
        }
        (pts, tris, orig)
    }
}

fn check_options(o: &HybridOptions) -> Result<(), HybridError> {
    let bad = |name, value: f64, reason| Err(HybridError::Parameter { name, value, reason });
    if !(o.core_fraction > 0.0 && o.core_fraction < 1.0) {
        return bad("core fraction", o.core_fraction, "must lie strictly between 0 and 1");
    }
    if o.core_triangles != 0 && o.core_triangles < 4 {
        return bad("core triangles", o.core_triangles as f64, "must be at least 4");
    }
    if o.core_layers == 0 || o.core_layers > 16 {
        return bad("core layers", o.core_layers as f64, "must be 1 to 16");
    }
    match o.spacing {
        Spacing::Length(s) if !(s > 0.0 && s.is_finite()) => return bad("particle spacing", s, "must be positive and finite [m]"),
        Spacing::Count(n) if !(100..=50_000_000).contains(&n) => return bad("particle count", n as f64, "must be 100 to 5e7"),
        _ => {}
    }
    if !(o.density > 0.0 && o.density.is_finite()) {
        return bad("density", o.density, "must be positive and finite [kg/m^3]");
    }
    if !(1000..=50_000_000).contains(&o.field_voxels) {
        return bad("field voxels", o.field_voxels as f64, "must be 1e3 to 5e7");
    }
    Ok(())
}

/// Build the hybrid model of `wall`.
pub fn build(wall: &Wall, o: &HybridOptions) -> Result<HybridModel, HybridError> {
    check_options(o)?;
    let t_start = Instant::now();
    let mut stats = BuildStats::default();
    let surf = &wall.surface;
    let wall_volume = surf.volume();
    if !(wall_volume > 0.0) {
        return Err(HybridError::Parts(format!("the wall boundary encloses {wall_volume:e} m^3; is it oriented outward?")));
    }
    // --- transmural field ---
    let h = (wall_volume / o.field_voxels as f64).cbrt();
    let mean_edge = (surf.area() / surf.n_triangles() as f64 * 2.3).sqrt();
    let wall_grid = TriangleGrid::new(surf.points(), surf.triangles(), mean_edge.max(0.5 * h));
    let field = transmural::solve(surf, &wall.parts, h, &wall_grid);
    stats.field_iterations = field.iterations;
    stats.field_s = t_start.elapsed().as_secs_f64();

    // --- FEM core ---
    let t0 = Instant::now();
    let closed = !wall.parts.contains(&WallPart::Base);
    let (mut n_tri, mut tries) = match o.core_triangles {
        0 => (if closed { AUTO_CORE_TRIANGLES_CLOSED } else { AUTO_CORE_TRIANGLES_BASE }, 3),
        n => (n, 1),
    };
    let (core_points, core_tets, core_faces, core_base_nodes, core_quality, core_volume) = loop {
        match build_core(wall, &field, &wall_grid, o, n_tri) {
            Ok(c) => break c,
            Err(HybridError::Core(msg)) if tries > 1 && msg.contains("twisted") => {
                tries -= 1;
                n_tri += n_tri / 2;
            }
            Err(e) => return Err(e),
        }
    };
    stats.core_s = t0.elapsed().as_secs_f64();

    // --- particles ---
    let t0 = Instant::now();
    let spacing = match o.spacing {
        Spacing::Length(s) => s,
        Spacing::Count(n) => ((wall_volume - core_volume).max(0.05 * wall_volume) / n as f64).cbrt(),
    };
    let fill = sample_inside(surf, spacing, o.density)?;
    let tet_grid = TetGrid::new(&core_points, &core_tets, 2.0 * spacing.max(h));
    let mut particles = Vec::with_capacity(fill.len());
    for p in &fill.positions {
        if tet_grid.locate(&core_points, p).is_none() {
            particles.push(*p);
        }
    }
    if particles.is_empty() {
        return Err(HybridError::Particles(format!("no lattice point of spacing {spacing:e} m lies in the shell between the core and the outer surface")));
    }
    let (outer_points, outer_tris, _) = wall.part(WallPart::Outer);
    let outer_edge = {
        let a: f64 = outer_tris.iter().map(|t| (outer_points[t[1]] - outer_points[t[0]]).cross(&(outer_points[t[2]] - outer_points[t[0]])).norm() * 0.5).sum();
        (a / outer_tris.len() as f64 * 2.3).sqrt()
    };
    let outer_grid = TriangleGrid::new(&outer_points, &outer_tris, outer_edge.max(0.5 * h));
    let core_face_grid = TriangleGrid::new(&core_points, &core_faces, 2.0 * h.max(spacing));
    let top = 1.0 - 1e-6;
    let outer_of = |p: &Vec3, fallbacks: &mut usize| -> u32 {
        let q = field.march_to_level(p, top, true, o.projection);
        let q = match q {
            Some(q) => q,
            None => {
                *fallbacks += 1;
                *p
            }
        };
        outer_grid.nearest(&outer_points, &outer_tris, &q, |_| true).map(|r| r.0 as u32).unwrap_or(0)
    };
    let core_of = |p: &Vec3, fallbacks: &mut usize| -> (u32, Vec3, [f64; 3]) {
        let q = match field.march_to_level(p, o.core_fraction, false, o.projection) {
            Some(q) => q,
            None => {
                *fallbacks += 1;
                *p
            }
        };
        let (f, x, b, _) = core_face_grid.nearest(&core_points, &core_faces, &q, |_| true).expect("the core has faces");
        (f as u32, x, b)
    };
    // --- shared voxels: the outer triangle above each wall voxel ---
    // Wall voxels in order of decreasing phi: a voxel takes the owner of the wall voxel one step
    // along the field from its centre when that one has an owner already (one field line each),
    // and marches to the outer surface itself otherwise (the outermost layer, and where field
    // lines leave through a base).
    let grid = field.grid;
    let mut voxel_owner = vec![VOXEL_OUTSIDE; grid.len()];
    let mut order: Vec<usize> = (0..grid.len()).filter(|&v| field.wall[v]).collect();
    order.sort_by(|&a, &b| field.phi[b].total_cmp(&field.phi[a]));
    let mut fv = 0;
    for &v in &order {
        let c = grid.centre(v);
        if tet_grid.locate(&core_points, &c).is_some() {
            voxel_owner[v] = VOXEL_CORE;
            continue;
        }
        let ahead = c + grid.h * field.dir_at(&c, o.projection);
        let inherited = grid.voxel_of(&ahead).map(|a| voxel_owner[grid.index(a[0], a[1], a[2])]).filter(|&w| w < VOXEL_CORE);
        voxel_owner[v] = match inherited {
            Some(w) => w,
            None => outer_of(&c, &mut fv),
        };
    }
    // Particles take their voxel's owner (so that RV(p_s) and the inside voxels of B(p_s) agree),
    // or march when their voxel is not a wall voxel.
    let mut fo = 0;
    let mut fc = 0;
    let mut keyed: Vec<(u32, u32, Vec3)> = particles
        .iter()
        .map(|p| {
            let from_voxel = grid.voxel_of(p).map(|a| voxel_owner[grid.index(a[0], a[1], a[2])]).filter(|&w| w < VOXEL_CORE);
            let t = match from_voxel {
                Some(w) => w,
                None => outer_of(p, &mut fo),
            };
            let (f, _, _) = core_of(p, &mut fc);
            (t, f, *p)
        })
        .collect();
    stats.fallback_particle_outer = fo;
    stats.fallback_particle_core = fc;
    keyed.sort_by(|a, b| a.0.cmp(&b.0).then(a.2.x.total_cmp(&b.2.x)).then(a.2.y.total_cmp(&b.2.y)).then(a.2.z.total_cmp(&b.2.z)));
    let particles: Vec<Vec3> = keyed.iter().map(|k| k.2).collect();
    let particle_outer_tri: Vec<u32> = keyed.iter().map(|k| k.0).collect();
    let particle_core_face: Vec<u32> = keyed.iter().map(|k| k.1).collect();
    let mut tri_particle_ptr = vec![0u32; outer_tris.len() + 1];
    for &t in &particle_outer_tri {
        tri_particle_ptr[t as usize + 1] += 1;
    }
    for t in 0..outer_tris.len() {
        tri_particle_ptr[t + 1] += tri_particle_ptr[t];
    }
    let particle_mass = vec![o.density * spacing.powi(3); particles.len()];
    stats.particles_s = t0.elapsed().as_secs_f64();

    // --- skin ---
    let t0 = Instant::now();
    let mut fs = 0;
    let mut skin_face = Vec::with_capacity(outer_points.len());
    let mut skin_bary = Vec::with_capacity(outer_points.len());
    let mut skin_offset = Vec::with_capacity(outer_points.len());
    for p in &outer_points {
        let (f, x, b) = core_of(p, &mut fs);
        skin_face.push(f);
        skin_bary.push(b);
        skin_offset.push(p - x);
    }
    stats.fallback_skin = fs;

    // --- activation regions: nv(p_s) grows by rings of triangles until RV(p_s) holds
    // `min_region_particles` (at most MAX_RINGS rings, further only while empty) ---
    let outer_adjacency = OuterAdjacency::new(outer_points.len(), &outer_tris);
    let count = |t: u32| (tri_particle_ptr[t as usize + 1] - tri_particle_ptr[t as usize]) as usize;
    let mut in_patch = vec![false; outer_tris.len()];
    let mut region_rings = Vec::with_capacity(outer_points.len());
    let mut region_box = Vec::with_capacity(outer_points.len());
    for s in 0..outer_points.len() {
        let mut n = 0;
        let (patch, rings) = outer_adjacency.patch(&outer_tris, s, None, Marks::Flags(&mut in_patch), |r, added| {
            n += added.iter().map(|&t| count(t)).sum::<usize>();
            !(n >= o.min_region_particles || (r >= MAX_RINGS && n > 0) || r >= 2 * MAX_RINGS)
        });
        region_rings.push(rings.min(255) as u8);
        let (mut lo, mut hi) = ([u32::MAX; 3], [0u32; 3]);
        for &t in &patch {
            for q in tri_particle_ptr[t as usize] as usize..tri_particle_ptr[t as usize + 1] as usize {
                if let Some(c) = grid.voxel_of(&particles[q]) {
                    for a in 0..3 {
                        lo[a] = lo[a].min(c[a] as u32);
                        hi[a] = hi[a].max(c[a] as u32);
                    }
                }
            }
        }
        if lo[0] == u32::MAX {
            let c = grid.voxel_of(&outer_points[s]).unwrap_or([0, 0, 0]);
            lo = [c[0] as u32, c[1] as u32, c[2] as u32];
            hi = lo;
        }
        // One voxel of margin, clamped to the grid.
        let mut b = [0u32; 6];
        for a in 0..3 {
            b[a] = lo[a].saturating_sub(1);
            b[a + 3] = (hi[a] + 2).min(grid.dims[a] as u32);
        }
        region_box.push(b);
    }
    stats.regions_s = t0.elapsed().as_secs_f64();
    stats.total_s = t_start.elapsed().as_secs_f64();
    Ok(HybridModel {
        options: *o,
        wall_volume,
        core_points,
        core_tets,
        core_faces,
        core_base_nodes,
        core_quality,
        spacing,
        particles,
        particle_mass,
        particle_outer_tri,
        particle_core_face,
        tri_particle_ptr,
        outer_points,
        outer_tris,
        region_rings,
        outer_adjacency,
        region_box,
        skin_face,
        skin_bary,
        skin_offset,
        grid,
        voxel_owner,
        stats,
    })
}

type Core = (Vec<Vec3>, Vec<[usize; 4]>, Vec<[usize; 3]>, Vec<usize>, CoreQuality, f64);

/// The FEM core: the inner surface simplified to `n_tri` triangles, lifted into the wall,
/// offset in layers along the field and split into tets.
fn build_core(wall: &Wall, field: &Transmural, wall_grid: &TriangleGrid, o: &HybridOptions, n_tri: usize) -> Result<Core, HybridError> {
    let surf = &wall.surface;
    let field = field;
    let wall_grid = wall_grid;
    let (ipts, itris, _) = wall.part(WallPart::Inner);
    let mut coarse = simplify(&ipts, &itris, n_tri);
    balance_on_surface(&mut coarse, surf, &wall.parts, wall_grid, field, 0.95 * o.core_fraction);
    if coarse.triangles.len() < 4 {
        return Err(HybridError::Core(format!("the inner surface simplified to {} triangles", coarse.triangles.len())));
    }
    let nv = coarse.points.len();
    let layers = o.core_layers;
    let mut core_points = Vec::with_capacity(nv * (layers + 1));
    core_points.extend(coarse.points.iter().copied());
    // Layer l of vertex v sits at phi_b + l/L (f - phi_b), phi_b the level of the (lifted)
    // inner vertex; at least a quarter of the core fraction above it, so that no prism is flat.
    // Vertices on a boundary loop (a base or valve ring) go straight towards the nearest point of
    // the outer surface instead, across the ring: the field is degenerate along the rim.
    let phi_b: Vec<f64> = coarse.points.iter().map(|p| field.phi_at(p)).collect();
    let outer_dir: Vec<Vec3> = coarse
        .points
        .iter()
        .map(|p| match wall_grid.nearest(surf.points(), surf.triangles(), p, |t| wall.parts[t] == WallPart::Outer) {
            Some((_, q, _, _)) => q - p,
            None => Vec3::zeros(),
        })
        .collect();
    for l in 1..=layers {
        let frac = l as f64 / layers as f64;
        for (v, p) in coarse.points.iter().enumerate() {
            let straight = p + o.core_fraction * frac * outer_dir[v];
            if coarse.boundary[v] || phi_b[v] >= 0.95 {
                core_points.push(straight);
                continue;
            }
            let span = (o.core_fraction - phi_b[v]).max(0.25 * o.core_fraction);
            let level = (phi_b[v] + span * frac).min(0.95);
            let q = field.march_to_level(p, level, true, o.projection).or_else(|| field.march_to_level(p, level, true, Projection::Transmural)).unwrap_or(straight);
            core_points.push(q);
        }
    }
    // Prisms: the inner triangles face the cavity and the layers rise into the wall, so every
    // tet of a sound prism has negative signed volume as split. A twisted prism (offsets of
    // neighbouring vertices pointing apart, e.g. along a valve ring) shows a tet of the other
    // sign; the offsets of its vertices are then smoothed towards their neighbours' until none
    // is left.
    let prisms: Vec<[usize; 4]> = (0..layers)
        .flat_map(|l| coarse.triangles.iter().flat_map(move |tri| split_prism([tri[0] + l * nv, tri[1] + l * nv, tri[2] + l * nv], nv)))
        .collect();
    let tet_vol = |pts: &[Vec3], t: &[usize; 4]| signed_volume(&pts[t[0]], &pts[t[1]], &pts[t[2]], &pts[t[3]]);
    let mut vnbrs: Vec<Vec<usize>> = vec![vec![]; nv];
    for tri in &coarse.triangles {
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
        let scale = core_points.iter().take(nv).zip(core_points.iter().skip(layers * nv)).map(|(a, b)| (b - a).norm()).fold(0.0, f64::max).max(1e-9);
        let bad: Vec<usize> = prisms.iter().filter(|t| tet_vol(&core_points, t) > -1e-6 * scale.powi(3)).flat_map(|t| t.iter().map(|&n| n % nv)).collect();
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
    let mut core_tets = Vec::with_capacity(prisms.len());
    for (t, tet) in prisms.iter().enumerate() {
        let v = tet_vol(&core_points, tet);
        if !(v < 0.0) {
            let hint = if o.projection == Projection::Radial {
                "; the radial projection cannot serve this wall (it is not star-shaped about its mass centre): use the transmural projection"
            } else {
                ""
            };
            return Err(HybridError::Core(format!(
                "prism {} (coarse inner triangle {}) stays twisted after smoothing its offsets; try more core triangles or a smaller core fraction{hint}",
                t / 3,
                (t / 3) % coarse.triangles.len()
            )));
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
    let vols: Vec<f64> = core_tets.iter().map(|t| signed_volume(&core_points[t[0]], &core_points[t[1]], &core_points[t[2]], &core_points[t[3]])).collect();
    let core_quality = CoreQuality {
        min_dihedral_deg: mesh.min_dihedral_deg(),
        min_volume: vols.iter().copied().fold(f64::INFINITY, f64::min),
        max_volume: vols.iter().copied().fold(0.0, f64::max),
    };
    let core_volume: f64 = vols.iter().sum();
    let mut core_base_nodes: Vec<usize> = Vec::new();
    for (v, &b) in coarse.boundary.iter().enumerate() {
        if b {
            for l in 0..=layers {
                core_base_nodes.push(v + l * nv);
            }
        }
    }
    core_base_nodes.sort_unstable();
    Ok((core_points, core_tets, core_faces, core_base_nodes, core_quality, core_volume))
}

/// Move the vertices of the coarse inner surface along the transmural direction until the
/// coarse surface lies in the wall: chords of a curved surface cut into the cavity, and the core
/// would otherwise take cavity volume (the wall region this leaves between the coarse and the
/// true inner surface is filled with particles). The signed depth of a sample point is its
/// distance to the nearest inner triangle, negative on the cavity side; each vertex rises by the
/// deepest cavity-side depth among the samples of its triangles it weighs most in. Boundary
/// (base) vertices stay.
fn balance_on_surface(coarse: &mut crate::mesh::simplify::Simplified, surf: &TriSurface, parts: &[WallPart], grid: &TriangleGrid, field: &Transmural, max_level: f64) {
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
                    let Some((t, q, _, d)) = grid.nearest(pts, tris, &p, |t| parts[t] == WallPart::Inner) else { continue };
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

/// The 3 tets of the prism over `bottom` (top vertex of `v` is `v + nv`), split so that every
/// quadrilateral side takes the diagonal through its smallest-index vertex (Dompierre et al.
/// 1999): neighbouring prisms then agree on their shared sides, and the tets conform.
fn split_prism(bottom: [usize; 3], nv: usize) -> [[usize; 4]; 3] {
    // Rotate so that the smallest index comes first (orientation kept).
    let m = (0..3).min_by_key(|&k| bottom[k]).unwrap();
    let (v1, v2, v3) = (bottom[m], bottom[(m + 1) % 3], bottom[(m + 2) % 3]);
    let (v4, v5, v6) = (v1 + nv, v2 + nv, v3 + nv);
    if v2.min(v6) < v3.min(v5) {
        [[v1, v2, v3, v6], [v1, v2, v6, v5], [v1, v5, v6, v4]]
    } else {
        [[v1, v2, v3, v5], [v1, v5, v3, v6], [v1, v5, v6, v4]]
    }
}

/// The triangles already in a patch: one flag per triangle (the builder's sweep over every
/// vertex; all false on entry and on exit), or a sorted list (one region on demand, a few hundred
/// triangles, without touching a flag per surface triangle).
enum Marks<'a> {
    Flags(&'a mut [bool]),
    Sorted(Vec<u32>),
}

impl Marks<'_> {
    /// Mark `t`; false if it was marked already.
    fn insert(&mut self, t: u32) -> bool {
        match self {
            Marks::Flags(f) => !std::mem::replace(&mut f[t as usize], true),
            Marks::Sorted(v) => match v.binary_search(&t) {
                Ok(_) => false,
                Err(k) => {
                    v.insert(k, t);
                    true
                }
            },
        }
    }

    fn reset(&mut self, patch: &[u32]) {
        if let Marks::Flags(f) = self {
            patch.iter().for_each(|&t| f[t as usize] = false);
        }
    }
}

/// Adjacency of the outer surface: the triangles around each vertex (CSR) and the triangle
/// across each edge (`u32::MAX` on an open boundary).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OuterAdjacency {
    pub vtri_ptr: Vec<u32>,
    pub vtris: Vec<u32>,
    pub across: Vec<[u32; 3]>,
}

impl OuterAdjacency {
    /// Of `tris` over `nv` vertices.
    pub fn new(nv: usize, tris: &[[usize; 3]]) -> OuterAdjacency {
        let mut vtri_ptr = vec![0u32; nv + 1];
        for tri in tris {
            for &v in tri {
                vtri_ptr[v + 1] += 1;
            }
        }
        for v in 0..nv {
            vtri_ptr[v + 1] += vtri_ptr[v];
        }
        let mut fill = vtri_ptr.clone();
        let mut vtris = vec![0u32; 3 * tris.len()];
        for (t, tri) in tris.iter().enumerate() {
            for &v in tri {
                vtris[fill[v] as usize] = t as u32;
                fill[v] += 1;
            }
        }
        let mut across = vec![[u32::MAX; 3]; tris.len()];
        let mut keyed: Vec<(usize, usize, u32, u8)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                keyed.push((a.min(b), a.max(b), t as u32, k as u8));
            }
        }
        keyed.sort_unstable();
        for w in keyed.windows(2) {
            if (w[0].0, w[0].1) == (w[1].0, w[1].1) {
                across[w[0].2 as usize][w[0].3 as usize] = w[1].2;
                across[w[1].2 as usize][w[1].3 as usize] = w[0].2;
            }
        }
        OuterAdjacency { vtri_ptr, vtris, across }
    }

    fn around(&self, v: usize) -> &[u32] { &self.vtris[self.vtri_ptr[v] as usize..self.vtri_ptr[v + 1] as usize] }

    /// The triangles within `rings` rings of vertex `s` (sorted), growing one ring at a time
    /// while `more(rings so far, triangles added)` says so when `rings` is `None`. Returns the
    /// patch and the rings used.
    fn patch(&self, tris: &[[usize; 3]], s: usize, rings: Option<usize>, mut in_patch: Marks<'_>, mut more: impl FnMut(usize, &[u32]) -> bool) -> (Vec<u32>, usize) {
        let mut patch: Vec<u32> = Vec::new();
        for &t in self.around(s) {
            in_patch.insert(t);
            patch.push(t);
        }
        let mut ring_start = 0;
        let mut r = 1;
        loop {
            let go_on = match rings {
                Some(n) => r < n,
                None => more(r, &patch[ring_start..]),
            };
            if !go_on {
                break;
            }
            let ring_end = patch.len();
            for i in ring_start..ring_end {
                for &v in &tris[patch[i] as usize] {
                    for &t in self.around(v) {
                        if in_patch.insert(t) {
                            patch.push(t);
                        }
                    }
                }
            }
            if patch.len() == ring_end {
                break; // the whole surface
            }
            ring_start = ring_end;
            r += 1;
        }
        in_patch.reset(&patch);
        patch.sort_unstable();
        (patch, r)
    }

    /// Boundary vertices of a patch (sorted triangles), in the order its directed boundary
    /// edges chain (other loops' vertices, if any, appended unordered).
    fn rim(&self, tris: &[[usize; 3]], patch: &[u32]) -> Vec<u32> {
        let inside = |t: u32| patch.binary_search(&t).is_ok();
        let mut next: Vec<(u32, u32)> = Vec::new();
        for &t in patch {
            let tri = tris[t as usize];
            for k in 0..3 {
                let o = self.across[t as usize][k];
                if o == u32::MAX || !inside(o) {
                    next.push((tri[k] as u32, tri[(k + 1) % 3] as u32));
                }
            }
        }
        next.sort_unstable();
        let mut loop_v: Vec<u32> = Vec::new();
        if let Some(&(start, _)) = next.first() {
            let mut v = start;
            for _ in 0..next.len() {
                loop_v.push(v);
                match next.binary_search_by_key(&v, |e| e.0) {
                    Ok(k) if next[k].1 != start => v = next[k].1,
                    _ => break,
                }
            }
            let mut seen = loop_v.clone();
            seen.sort_unstable();
            let mut rest: Vec<u32> = next.iter().map(|e| e.0).filter(|v| seen.binary_search(v).is_err()).collect();
            rest.dedup();
            loop_v.extend(rest);
        }
        loop_v
    }
}

impl HybridModel {
    /// Number of activation regions (one per outer-surface vertex).
    pub fn n_regions(&self) -> usize { self.region_box.len() }

    /// nv(p_s) of region `s`: its outer triangles, sorted (grown from the stored ring count in
    /// microseconds).
    pub fn region_triangles(&self, s: usize) -> Vec<u32> {
        self.outer_adjacency.patch(&self.outer_tris, s, Some(self.region_rings[s] as usize), Marks::Sorted(Vec::new()), |_, _| false).0
    }

    /// RV(p_s): the particles of region `s`, as ranges into [`HybridModel::particles`] (one per
    /// triangle of nv(p_s): particles are sorted by the outer triangle above them).
    pub fn region_particle_ranges(&self, s: usize) -> Vec<std::ops::Range<usize>> {
        self.region_triangles(s).iter().map(|&t| self.tri_particle_ptr[t as usize] as usize..self.tri_particle_ptr[t as usize + 1] as usize).collect()
    }

    /// Number of particles in RV(p_s).
    pub fn region_len(&self, s: usize) -> usize { self.region_particle_ranges(s).iter().map(|r| r.len()).sum() }

    /// Core faces under RV(p_s) (the faces below its particles; the skin face of `s` if it has
    /// none), sorted.
    pub fn region_core_faces(&self, s: usize) -> Vec<u32> {
        let mut f: Vec<u32> = self.region_particle_ranges(s).into_iter().flatten().map(|q| self.particle_core_face[q]).collect();
        if f.is_empty() {
            f.push(self.skin_face[s]);
        }
        f.sort_unstable();
        f.dedup();
        f
    }

    /// The boundary vertices of nv(p_s) (outer vertex indices), in loop order.
    pub fn region_rim(&self, s: usize) -> Vec<u32> { self.outer_adjacency.rim(&self.outer_tris, &self.region_triangles(s)) }

    /// C(p_s): the projections on the core of nv(p_s)'s boundary vertices \[m\].
    pub fn region_curve(&self, s: usize) -> Vec<Vec3> { self.region_rim(s).iter().map(|&v| self.skin_anchor(v as usize)).collect() }

    /// Rest anchor point of outer vertex `v` on its core face \[m\].
    pub fn skin_anchor(&self, v: usize) -> Vec3 {
        let f = self.core_faces[self.skin_face[v] as usize];
        let b = self.skin_bary[v];
        b[0] * self.core_points[f[0]] + b[1] * self.core_points[f[1]] + b[2] * self.core_points[f[2]]
    }

    /// Total core volume \[m^3\].
    pub fn core_volume(&self) -> f64 {
        self.core_tets.iter().map(|t| signed_volume(&self.core_points[t[0]], &self.core_points[t[1]], &self.core_points[t[2]], &self.core_points[t[3]])).sum()
    }

    /// Shell volume represented by the particles (lattice cells) \[m^3\].
    pub fn shell_volume(&self) -> f64 { self.particles.len() as f64 * self.spacing.powi(3) }

    /// B(p_s) with its labels and gradient field, computed from the shared voxels (see
    /// [`RegionField`]).
    pub fn region_field(&self, s: usize) -> RegionField {
        let b = self.region_box[s];
        let dims = [(b[3] - b[0]) as usize, (b[4] - b[1]) as usize, (b[5] - b[2]) as usize];
        let n = dims[0] * dims[1] * dims[2];
        let tris = self.region_triangles(s);
        let tris = &tris[..];
        let global = |i: usize, j: usize, k: usize| self.grid.index(b[0] as usize + i, b[1] as usize + j, b[2] as usize + k);
        let local = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        let mut label = vec![VoxelLabel::Outside; n];
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let o = self.voxel_owner[global(i, j, k)];
                    if o < VOXEL_CORE && tris.binary_search(&o).is_ok() {
                        label[local(i, j, k)] = VoxelLabel::Inside;
                    }
                }
            }
        }
        // Boundary: inside voxels with a face-neighbour outside the region (or the box).
        let snapshot = label.clone();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    if snapshot[local(i, j, k)] != VoxelLabel::Inside {
                        continue;
                    }
                    let c = [i as isize, j as isize, k as isize];
                    let mut edge = false;
                    for a in 0..3 {
                        for s in [-1, 1] {
                            let mut d = c;
                            d[a] += s;
                            if d[a] < 0 || d[a] >= dims[a] as isize || snapshot[local(d[0] as usize, d[1] as usize, d[2] as usize)] == VoxelLabel::Outside {
                                edge = true;
                            }
                        }
                    }
                    if edge {
                        label[local(i, j, k)] = VoxelLabel::Boundary;
                    }
                }
            }
        }
        // Gradient: the unit vector to the nearest interior voxel (or, if the region has none,
        // the nearest boundary voxel), by exact Euclidean search over the box (a few hundred
        // voxels).
        let target = if label.contains(&VoxelLabel::Inside) { VoxelLabel::Inside } else { VoxelLabel::Boundary };
        let ijk = |v: usize| [(v % dims[0]) as f64, ((v / dims[0]) % dims[1]) as f64, (v / (dims[0] * dims[1])) as f64];
        let targets: Vec<[f64; 3]> = (0..n).filter(|&v| label[v] == target).map(ijk).collect();
        let gradient = (0..n)
            .map(|v| {
                if label[v] == target || targets.is_empty() {
                    return [0.0f32; 3];
                }
                let p = ijk(v);
                let mut best = (f64::INFINITY, [0.0; 3]);
                for t in &targets {
                    let d2 = (t[0] - p[0]).powi(2) + (t[1] - p[1]).powi(2) + (t[2] - p[2]).powi(2);
                    if d2 < best.0 {
                        best = (d2, *t);
                    }
                }
                let d = Vec3::new(best.1[0] - p[0], best.1[1] - p[1], best.1[2] - p[2]).normalize();
                [d.x as f32, d.y as f32, d.z as f32]
            })
            .collect();
        let origin = self.grid.origin + Vec3::new(b[0] as f64, b[1] as f64, b[2] as f64) * self.grid.h;
        RegionField { origin, h: self.grid.h, dims, label, gradient }
    }
}

/// Label of a voxel of B(p_s).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VoxelLabel {
    /// Not in RV(p_s).
    Outside,
    /// In RV(p_s), away from its boundary.
    Inside,
    /// In RV(p_s), with a face-neighbour outside it (or the box edge): the confinement layer.
    Boundary,
}

/// B(p_s): a voxel box (x fastest) with labels and the unit gradient field (Fig. 5): at
/// boundary and outside voxels it points to the nearest interior voxel, zero inside.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionField {
    /// Corner of the box \[m\].
    pub origin: Vec3,
    /// Voxel edge \[m\].
    pub h: f64,
    pub dims: [usize; 3],
    pub label: Vec<VoxelLabel>,
    pub gradient: Vec<[f32; 3]>,
}
