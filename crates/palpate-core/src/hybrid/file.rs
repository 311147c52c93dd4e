//! Saving and loading a compiled [`HybridModel`]: one versioned binary file with a checksum.
//!
//! Layout (little endian):
//!
//! ```text
//! 0   16 bytes  magic "PALPATE\0HYBRID\0\0"
//! 16  u32       format version (FORMAT_VERSION)
//! 20  u32       reserved (0)
//! 24  u64       payload length in bytes
//! 32  u64       FNV-1a 64 checksum of the payload
//! 40  payload   the model's fields in a fixed order; every array as a u64 count then its items
//! ```
//!
//! Loading checks, in order: the magic (a foreign file), the version, the length (a truncated
//! file), the checksum (a corrupted one), then the structure (every index in range, every
//! offset table monotone), so that a loaded model is as valid as a built one. Saving then
//! loading gives a model equal to the original, field by field and bit by bit.

use super::build::{BuildStats, CoreQuality, HybridModel, HybridOptions, OuterAdjacency, Spacing};
use super::transmural::{Projection, VoxelGrid};
use crate::error::ModelFileError;
use crate::math::Vec3;

/// The first 16 bytes of a palpate model file.
pub const MAGIC: &[u8; 16] = b"PALPATE\0HYBRID\0\0";
/// The format version this palpate writes and reads.
pub const FORMAT_VERSION: u32 = 1;
const HEADER: usize = 40;

/// FNV-1a, 64 bit.
pub fn checksum(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

struct W(Vec<u8>);

impl W {
    fn u8(&mut self, x: u8) { self.0.push(x); }
    fn u32(&mut self, x: u32) { self.0.extend_from_slice(&x.to_le_bytes()); }
    fn u64(&mut self, x: u64) { self.0.extend_from_slice(&x.to_le_bytes()); }
    fn f64(&mut self, x: f64) { self.0.extend_from_slice(&x.to_le_bytes()); }
    fn vec3(&mut self, v: &Vec3) {
        self.f64(v.x);
        self.f64(v.y);
        self.f64(v.z);
    }
    fn vec3s(&mut self, v: &[Vec3]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|p| self.vec3(p));
    }
    fn f64s(&mut self, v: &[f64]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.f64(x));
    }
    fn u32s(&mut self, v: &[u32]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.u32(x));
    }
    fn idx<const N: usize>(&mut self, v: &[[usize; N]]) {
        self.u64(v.len() as u64);
        v.iter().flatten().for_each(|&x| self.u32(x as u32));
    }
    fn usizes(&mut self, v: &[usize]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.u32(x as u32));
    }
}

struct R<'a> {
    b: &'a [u8],
    off: usize,
    path: &'a str,
}

type Res<T> = Result<T, ModelFileError>;

impl<'a> R<'a> {
    fn take(&mut self, n: usize, field: &'static str) -> Res<&'a [u8]> {
        if self.b.len() - self.off < n {
            return Err(ModelFileError::Truncated { path: self.path.into(), field, offset: self.off + HEADER, need: n, have: self.b.len() + HEADER });
        }
        let s = &self.b[self.off..self.off + n];
        self.off += n;
        Ok(s)
    }
    fn u8(&mut self, f: &'static str) -> Res<u8> { Ok(self.take(1, f)?[0]) }
    fn u32(&mut self, f: &'static str) -> Res<u32> { Ok(u32::from_le_bytes(self.take(4, f)?.try_into().unwrap())) }
    fn u64(&mut self, f: &'static str) -> Res<u64> { Ok(u64::from_le_bytes(self.take(8, f)?.try_into().unwrap())) }
    fn f64(&mut self, f: &'static str) -> Res<f64> { Ok(f64::from_le_bytes(self.take(8, f)?.try_into().unwrap())) }
    fn count(&mut self, item: usize, f: &'static str) -> Res<usize> {
        let n = self.u64(f)?;
        let left = (self.b.len() - self.off) as u64;
        if n.saturating_mul(item as u64) > left {
            return Err(ModelFileError::Truncated { path: self.path.into(), field: f, offset: self.off + HEADER, need: n.saturating_mul(item as u64).min(usize::MAX as u64) as usize, have: self.b.len() + HEADER });
        }
        Ok(n as usize)
    }
    fn vec3(&mut self, f: &'static str) -> Res<Vec3> { Ok(Vec3::new(self.f64(f)?, self.f64(f)?, self.f64(f)?)) }
    fn vec3s(&mut self, f: &'static str) -> Res<Vec<Vec3>> {
        let n = self.count(24, f)?;
        (0..n).map(|_| self.vec3(f)).collect()
    }
    fn f64s(&mut self, f: &'static str) -> Res<Vec<f64>> {
        let n = self.count(8, f)?;
        (0..n).map(|_| self.f64(f)).collect()
    }
    fn u32s(&mut self, f: &'static str) -> Res<Vec<u32>> {
        let n = self.count(4, f)?;
        (0..n).map(|_| self.u32(f)).collect()
    }
    fn idx<const N: usize>(&mut self, f: &'static str) -> Res<Vec<[usize; N]>> {
        let n = self.count(4 * N, f)?;
        (0..n)
            .map(|_| {
                let mut a = [0usize; N];
                for x in a.iter_mut() {
                    *x = self.u32(f)? as usize;
                }
                Ok(a)
            })
            .collect()
    }
    fn usizes(&mut self, f: &'static str) -> Res<Vec<usize>> {
        let n = self.count(4, f)?;
        (0..n).map(|_| Ok(self.u32(f)? as usize)).collect()
    }
}

/// The model as the bytes of a model file.
pub fn to_bytes(m: &HybridModel) -> Vec<u8> {
    let mut w = W(Vec::new());
    let o = &m.options;
    w.u8(match o.projection {
        Projection::Transmural => 0,
        Projection::Radial => 1,
    });
    w.f64(o.core_fraction);
    w.u64(o.core_triangles as u64);
    w.u64(o.core_layers as u64);
    match o.spacing {
        Spacing::Length(s) => {
            w.u8(0);
            w.f64(s);
        }
        Spacing::Count(n) => {
            w.u8(1);
            w.u64(n as u64);
        }
    }
    w.f64(o.density);
    w.u64(o.min_region_particles as u64);
    w.u64(o.field_voxels as u64);
    w.f64(m.wall_volume);
    w.vec3s(&m.core_points);
    w.idx(&m.core_tets);
    w.idx(&m.core_faces);
    w.usizes(&m.core_base_nodes);
    let q = &m.core_quality;
    w.f64(q.min_dihedral_deg);
    w.f64(q.min_volume);
    w.f64(q.max_volume);
    w.f64(m.spacing);
    w.vec3s(&m.particles);
    w.f64s(&m.particle_mass);
    w.u32s(&m.particle_outer_tri);
    w.u32s(&m.particle_core_face);
    w.u32s(&m.tri_particle_ptr);
    w.vec3s(&m.outer_points);
    w.idx(&m.outer_tris);
    w.u64(m.region_rings.len() as u64);
    m.region_rings.iter().for_each(|&r| w.u8(r));
    w.u64(m.region_box.len() as u64);
    m.region_box.iter().flatten().for_each(|&x| w.u32(x));
    w.u32s(&m.skin_face);
    w.u64(m.skin_bary.len() as u64);
    m.skin_bary.iter().flatten().for_each(|&x| w.f64(x));
    w.vec3s(&m.skin_offset);
    w.vec3(&m.grid.origin);
    w.f64(m.grid.h);
    m.grid.dims.iter().for_each(|&d| w.u64(d as u64));
    w.u32s(&m.voxel_owner);
    let s = &m.stats;
    for x in [s.field_s, s.core_s, s.particles_s, s.regions_s, s.total_s] {
        w.f64(x);
    }
    for x in [s.field_iterations, s.fallback_particle_outer, s.fallback_particle_core, s.fallback_skin] {
        w.u64(x as u64);
    }
    let payload = w.0;
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&checksum(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

/// Read a model from the bytes of a model file; `path` names it in errors.
pub fn from_bytes(bytes: &[u8], path: &str) -> Result<HybridModel, ModelFileError> {
    if bytes.len() < 16 || &bytes[..16] != MAGIC {
        return Err(ModelFileError::NotAModel { path: path.into() });
    }
    if bytes.len() < HEADER {
        return Err(ModelFileError::Truncated { path: path.into(), field: "header", offset: 16, need: HEADER - 16, have: bytes.len() });
    }
    let version = u32::from_le_bytes(bytes[16..20].try_into().unwrap());
    if version != FORMAT_VERSION {
        return Err(ModelFileError::Version { path: path.into(), found: version, supported: FORMAT_VERSION });
    }
    let len = u64::from_le_bytes(bytes[24..32].try_into().unwrap());
    let stored = u64::from_le_bytes(bytes[32..40].try_into().unwrap());
    let have = (bytes.len() - HEADER) as u64;
    if len > have {
        return Err(ModelFileError::Truncated { path: path.into(), field: "payload", offset: HEADER, need: len.min(usize::MAX as u64) as usize, have: bytes.len() });
    }
    if len < have {
        return Err(ModelFileError::Corrupt { path: path.into(), reason: format!("{} bytes after the end of the model", have - len) });
    }
    let payload = &bytes[HEADER..];
    let computed = checksum(payload);
    if computed != stored {
        return Err(ModelFileError::Checksum { path: path.into(), stored, computed });
    }
    let mut r = R { b: payload, off: 0, path };
    let projection = match r.u8("projection")? {
        0 => Projection::Transmural,
        1 => Projection::Radial,
        x => return Err(ModelFileError::Corrupt { path: path.into(), reason: format!("projection code {x}") }),
    };
    let core_fraction = r.f64("core fraction")?;
    let core_triangles = r.u64("core triangles")? as usize;
    let core_layers = r.u64("core layers")? as usize;
    let spacing = match r.u8("spacing kind")? {
        0 => Spacing::Length(r.f64("spacing")?),
        1 => Spacing::Count(r.u64("spacing")? as usize),
        x => return Err(ModelFileError::Corrupt { path: path.into(), reason: format!("spacing code {x}") }),
    };
    let options = HybridOptions {
        projection,
        core_fraction,
        core_triangles,
        core_layers,
        spacing,
        density: r.f64("density")?,
        min_region_particles: r.u64("min region particles")? as usize,
        field_voxels: r.u64("field voxels")? as usize,
    };
    let wall_volume = r.f64("wall volume")?;
    let core_points = r.vec3s("core points")?;
    let core_tets = r.idx::<4>("core tets")?;
    let core_faces = r.idx::<3>("core faces")?;
    let core_base_nodes = r.usizes("core base nodes")?;
    let core_quality = CoreQuality { min_dihedral_deg: r.f64("core quality")?, min_volume: r.f64("core quality")?, max_volume: r.f64("core quality")? };
    let spacing_m = r.f64("spacing")?;
    let particles = r.vec3s("particles")?;
    let particle_mass = r.f64s("particle masses")?;
    let particle_outer_tri = r.u32s("particle outer triangles")?;
    let particle_core_face = r.u32s("particle core faces")?;
    let tri_particle_ptr = r.u32s("particles per outer triangle")?;
    let outer_points = r.vec3s("outer points")?;
    let outer_tris = r.idx::<3>("outer triangles")?;
    let nr = r.count(1, "region rings")?;
    let region_rings: Vec<u8> = (0..nr).map(|_| r.u8("region rings")).collect::<Res<_>>()?;
    let nb = r.count(24, "region boxes")?;
    let mut region_box = Vec::with_capacity(nb);
    for _ in 0..nb {
        let mut b = [0u32; 6];
        for x in b.iter_mut() {
            *x = r.u32("region boxes")?;
        }
        region_box.push(b);
    }
    let skin_face = r.u32s("skin faces")?;
    let ns = r.count(24, "skin barycentric coordinates")?;
    let mut skin_bary = Vec::with_capacity(ns);
    for _ in 0..ns {
        skin_bary.push([r.f64("skin barycentric coordinates")?, r.f64("skin barycentric coordinates")?, r.f64("skin barycentric coordinates")?]);
    }
    let skin_offset = r.vec3s("skin offsets")?;
    let origin = r.vec3("voxel grid")?;
    let h = r.f64("voxel grid")?;
    let dims = [r.u64("voxel grid")? as usize, r.u64("voxel grid")? as usize, r.u64("voxel grid")? as usize];
    let voxel_owner = r.u32s("voxel owners")?;
    let mut t = [0.0; 5];
    for x in t.iter_mut() {
        *x = r.f64("build statistics")?;
    }
    let mut c = [0usize; 4];
    for x in c.iter_mut() {
        *x = r.u64("build statistics")? as usize;
    }
    if r.off != payload.len() {
        return Err(ModelFileError::Corrupt { path: path.into(), reason: format!("{} unread bytes at the end of the payload", payload.len() - r.off) });
    }
    let m = HybridModel {
        options,
        wall_volume,
        core_points,
        core_tets,
        core_faces,
        core_base_nodes,
        core_quality,
        spacing: spacing_m,
        particles,
        particle_mass,
        particle_outer_tri,
        particle_core_face,
        tri_particle_ptr,
        outer_points,
        outer_tris,
        region_rings,
        outer_adjacency: Default::default(),
        region_box,
        skin_face,
        skin_bary,
        skin_offset,
        grid: VoxelGrid { origin, h, dims },
        voxel_owner,
        stats: BuildStats {
            field_s: t[0],
            core_s: t[1],
            particles_s: t[2],
            regions_s: t[3],
            total_s: t[4],
            field_iterations: c[0],
            fallback_particle_outer: c[1],
            fallback_particle_core: c[2],
            fallback_skin: c[3],
        },
    };
    check_structure(&m).map_err(|reason| ModelFileError::Corrupt { path: path.into(), reason })?;
    let mut m = m;
    m.outer_adjacency = OuterAdjacency::new(m.outer_points.len(), &m.outer_tris);
    Ok(m)
}

/// Every index in range, every offset table monotone and of the right length.
fn check_structure(m: &HybridModel) -> Result<(), String> {
    let nc = m.core_points.len();
    let in_range = |what: &str, v: &mut dyn Iterator<Item = usize>, n: usize| -> Result<(), String> {
        for (i, x) in v.enumerate() {
            if x >= n {
                return Err(format!("{what}: entry {i} is {x}, out of range (< {n})"));
            }
        }
        Ok(())
    };
    in_range("core tets", &mut m.core_tets.iter().flatten().copied(), nc)?;
    in_range("core faces", &mut m.core_faces.iter().flatten().copied(), nc)?;
    in_range("core base nodes", &mut m.core_base_nodes.iter().copied(), nc)?;
    let (np, no, nt, nf) = (m.particles.len(), m.outer_points.len(), m.outer_tris.len(), m.core_faces.len());
    in_range("outer triangles", &mut m.outer_tris.iter().flatten().copied(), no)?;
    if m.particle_mass.len() != np || m.particle_outer_tri.len() != np || m.particle_core_face.len() != np {
        return Err("per-particle arrays of different lengths".into());
    }
    in_range("particle outer triangles", &mut m.particle_outer_tri.iter().map(|&x| x as usize), nt)?;
    in_range("particle core faces", &mut m.particle_core_face.iter().map(|&x| x as usize), nf)?;
    let offsets = |what: &str, ptr: &[u32], rows: usize, len: usize| -> Result<(), String> {
        if ptr.len() != rows + 1 || ptr[0] != 0 || *ptr.last().unwrap() as usize != len || ptr.windows(2).any(|w| w[0] > w[1]) {
            return Err(format!("{what}: offset table inconsistent ({} entries for {rows} rows over {len} items)", ptr.len()));
        }
        Ok(())
    };
    offsets("particles per outer triangle", &m.tri_particle_ptr, nt, np)?;
    if let Some(s) = m.region_rings.iter().position(|&r| r == 0) {
        return Err(format!("region {s}: zero rings"));
    }
    if m.region_rings.len() != no || m.region_box.len() != no || m.skin_face.len() != no || m.skin_bary.len() != no || m.skin_offset.len() != no {
        return Err("per-outer-vertex arrays of different lengths".into());
    }
    in_range("skin faces", &mut m.skin_face.iter().map(|&x| x as usize), nf)?;
    let g = &m.grid;
    if !(g.h > 0.0 && g.h.is_finite()) || g.dims.iter().any(|&d| d == 0 || d > 1 << 20) || m.voxel_owner.len() != g.dims.iter().product::<usize>() {
        return Err("voxel grid inconsistent".into());
    }
    for (s, b) in m.region_box.iter().enumerate() {
        for a in 0..3 {
            if b[a] >= b[a + 3] || b[a + 3] as usize > g.dims[a] {
                return Err(format!("region {s}: voxel box {b:?} outside the grid {:?}", g.dims));
            }
        }
    }
    let finite = m.core_points.iter().chain(&m.particles).chain(&m.outer_points).chain(&m.skin_offset).all(|p| p.iter().all(|x| x.is_finite()));
    if !finite {
        return Err("non-finite coordinates".into());
    }
    Ok(())
}

impl HybridModel {
    /// Save to `path` (see the module docs for the format).
    pub fn save(&self, path: &std::path::Path) -> Result<(), ModelFileError> {
        std::fs::write(path, to_bytes(self)).map_err(|e| ModelFileError::Io { path: path.display().to_string(), reason: e.to_string() })
    }

    /// Load from `path`.
    pub fn load(path: &std::path::Path) -> Result<HybridModel, ModelFileError> {
        let bytes = std::fs::read(path).map_err(|e| ModelFileError::Io { path: path.display().to_string(), reason: e.to_string() })?;
        from_bytes(&bytes, &path.display().to_string())
    }
}
