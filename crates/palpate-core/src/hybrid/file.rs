//! Saving and loading a compiled [`HybridModel`]: one versioned binary file with a checksum.
//! This module is the container (header, framing, array codecs); each part of the model writes,
//! reads and checks its own section (`write`, `read`, `check` in its module), in the order of
//! the table `SECTIONS`.
//!
//! Layout (little endian):
//!
//! ```text
//! 0   16 bytes  magic "PALPATE\0HYBRID\0\0"
//! 16  u32       format version (FORMAT_VERSION; OLDEST_FORMAT_VERSION and later are read)
//! 20  u32       reserved (0)
//! 24  u64       payload length in bytes
//! 32  u64       FNV-1a 64 checksum of the payload
//! 40  payload   the sections, one after the other; every array as a u64 count then its items
//! ```
//!
//! Loading checks, in order: the magic (a foreign file), the version, the length (a truncated
//! file), the checksum (a corrupted one), then the structure (every index in range, every
//! offset table monotone), so that a loaded model is as valid as a built one. Saving then
//! loading gives a model equal to the original, field by field and bit by bit.

// Untrusted bytes are read here: no unwrap, expect or unchecked indexing (`cargo clippy` denies
// them; every access goes through `get` and a typed error).
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use super::model::{self, HybridModel};
use super::{build, core, homogenise, options, outer, region_field, regions, shell, skin};
use crate::error::ModelFileError;
use crate::math::Vec3;

/// The first 16 bytes of a palpate model file.
pub const MAGIC: &[u8; 16] = b"PALPATE\0HYBRID\0\0";
/// The format version this palpate writes and reads.
pub const FORMAT_VERSION: u32 = 3;

/// The oldest format this palpate reads.
pub const OLDEST_FORMAT_VERSION: u32 = 1;
const HEADER: usize = 40;

/// A section of the payload: its part's writer, reader (into a model being assembled) and
/// structure check (once every section is read).
struct Section {
    write: fn(&HybridModel, &mut Writer),
    read: fn(&mut Reader, &mut HybridModel) -> Res<()>,
    check: fn(&HybridModel) -> Result<(), String>,
}

const fn section(
    write: fn(&HybridModel, &mut Writer),
    read: fn(&mut Reader, &mut HybridModel) -> Res<()>,
    check: fn(&HybridModel) -> Result<(), String>,
) -> Section {
    Section { write, read, check }
}

fn unchecked(_: &HybridModel) -> Result<(), String> {
    Ok(())
}

/// The sections of the payload, in file order.
const SECTIONS: [Section; 11] = [
    section(options::write, options::read, unchecked),
    section(model::write_wall, model::read_wall, unchecked),
    section(core::write, core::read, core::check),
    section(shell::write, shell::read, shell::check),
    section(outer::write, outer::read, outer::check),
    section(regions::write, regions::read, regions::check),
    section(skin::write, skin::read, skin::check),
    section(region_field::write, region_field::read, region_field::check),
    section(build::write_stats, build::read_stats, unchecked),
    section(homogenise::write, homogenise::read, homogenise::check),
    section(homogenise::write_active, homogenise::read_active, homogenise::check),
];

/// Sections a file of each format has: format 1 (palpate before the homogenised core) stops
/// before the homogenisation, which then loads empty (the core stiff as the tissue); format 2
/// (before 2026-12-08) before the active factor, which then loads empty (the core under the
/// active shell stiff as the tissue).
fn sections_of(version: u32) -> usize {
    match version {
        1 => SECTIONS.len() - 2,
        2 => SECTIONS.len() - 1,
        _ => SECTIONS.len(),
    }
}

/// FNV-1a, 64 bit.
pub fn checksum(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The writer of a payload.
pub(super) struct Writer(Vec<u8>);

impl Writer {
    pub(super) fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    pub(super) fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub(super) fn u64(&mut self, x: u64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub(super) fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub(super) fn vec3(&mut self, v: &Vec3) {
        self.f64(v.x);
        self.f64(v.y);
        self.f64(v.z);
    }
    pub(super) fn vec3s(&mut self, v: &[Vec3]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|p| self.vec3(p));
    }
    pub(super) fn f64s(&mut self, v: &[f64]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.f64(x));
    }
    pub(super) fn u32s(&mut self, v: &[u32]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.u32(x));
    }
    pub(super) fn bytes(&mut self, v: &[u8]) {
        self.u64(v.len() as u64);
        self.0.extend_from_slice(v);
    }
    /// Rows of `N` entries, each entry as `T`'s codec: rows of indices as u32, of values as f64.
    pub(super) fn rows<T: Copy, const N: usize>(&mut self, v: &[[T; N]], mut item: impl FnMut(&mut Self, T)) {
        self.u64(v.len() as u64);
        v.iter().flatten().for_each(|&x| item(self, x));
    }
    /// Rows of `N` indices, as u32.
    pub(super) fn idx<const N: usize>(&mut self, v: &[[usize; N]]) {
        self.rows(v, |w, x| w.u32(x as u32))
    }
    pub(super) fn usizes(&mut self, v: &[usize]) {
        self.u64(v.len() as u64);
        v.iter().for_each(|&x| self.u32(x as u32));
    }
}

/// The reader of a payload; `path` names the file in errors.
pub(super) struct Reader<'a> {
    b: &'a [u8],
    off: usize,
    path: &'a str,
}

pub(super) type Res<T> = Result<T, ModelFileError>;

impl<'a> Reader<'a> {
    /// A corrupted file, for `reason`.
    pub(super) fn corrupt(&self, reason: String) -> ModelFileError {
        ModelFileError::Corrupt { path: self.path.into(), reason }
    }
    fn take(&mut self, n: usize, field: &'static str) -> Res<&'a [u8]> {
        match self.off.checked_add(n).and_then(|end| self.b.get(self.off..end)) {
            Some(s) => {
                self.off += n;
                Ok(s)
            }
            None => Err(ModelFileError::Truncated { path: self.path.into(), field, offset: self.off + HEADER, need: n, have: self.b.len() + HEADER }),
        }
    }
    /// `N` bytes as an array (a short read is the truncation error of `take`).
    fn array_of<const N: usize>(&mut self, f: &'static str) -> Res<[u8; N]> {
        let s = self.take(N, f)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }
    pub(super) fn u8(&mut self, f: &'static str) -> Res<u8> {
        Ok(self.array_of::<1>(f)?[0])
    }
    pub(super) fn u32(&mut self, f: &'static str) -> Res<u32> {
        Ok(u32::from_le_bytes(self.array_of(f)?))
    }
    pub(super) fn u64(&mut self, f: &'static str) -> Res<u64> {
        Ok(u64::from_le_bytes(self.array_of(f)?))
    }
    pub(super) fn f64(&mut self, f: &'static str) -> Res<f64> {
        Ok(f64::from_le_bytes(self.array_of(f)?))
    }
    /// The count of an array of `item`-byte entries, checked against the bytes left.
    fn count(&mut self, item: usize, f: &'static str) -> Res<usize> {
        let n = self.u64(f)?;
        let left = self.b.len().saturating_sub(self.off) as u64;
        if n.saturating_mul(item as u64) > left {
            return Err(ModelFileError::Truncated {
                path: self.path.into(),
                field: f,
                offset: self.off + HEADER,
                need: n.saturating_mul(item as u64).min(usize::MAX as u64) as usize,
                have: self.b.len() + HEADER,
            });
        }
        Ok(n as usize)
    }
    /// An array of `item`-byte entries, each read by `one`.
    fn array<T>(&mut self, item: usize, f: &'static str, mut one: impl FnMut(&mut Self) -> Res<T>) -> Res<Vec<T>> {
        let n = self.count(item, f)?;
        (0..n).map(|_| one(self)).collect()
    }
    pub(super) fn vec3(&mut self, f: &'static str) -> Res<Vec3> {
        Ok(Vec3::new(self.f64(f)?, self.f64(f)?, self.f64(f)?))
    }
    pub(super) fn vec3s(&mut self, f: &'static str) -> Res<Vec<Vec3>> {
        self.array(24, f, |r| r.vec3(f))
    }
    pub(super) fn f64s(&mut self, f: &'static str) -> Res<Vec<f64>> {
        self.array(8, f, |r| r.f64(f))
    }
    pub(super) fn u32s(&mut self, f: &'static str) -> Res<Vec<u32>> {
        self.array(4, f, |r| r.u32(f))
    }
    pub(super) fn bytes(&mut self, f: &'static str) -> Res<Vec<u8>> {
        self.array(1, f, |r| r.u8(f))
    }
    /// Rows of `N` entries of `size` bytes, each read by `item` (see [`Writer::rows`]).
    pub(super) fn rows<T: Copy + Default, const N: usize>(
        &mut self,
        size: usize,
        f: &'static str,
        mut item: impl FnMut(&mut Self) -> Res<T>,
    ) -> Res<Vec<[T; N]>> {
        self.array(size * N, f, |r| {
            let mut a = [T::default(); N];
            for x in a.iter_mut() {
                *x = item(r)?;
            }
            Ok(a)
        })
    }
    pub(super) fn idx<const N: usize>(&mut self, f: &'static str) -> Res<Vec<[usize; N]>> {
        self.rows(4, f, |r| Ok(r.u32(f)? as usize))
    }
    pub(super) fn usizes(&mut self, f: &'static str) -> Res<Vec<usize>> {
        self.array(4, f, |r| Ok(r.u32(f)? as usize))
    }
}

/// The model as the bytes of a model file.
pub fn to_bytes(m: &HybridModel) -> Vec<u8> {
    let mut w = Writer(Vec::new());
    for s in &SECTIONS {
        (s.write)(m, &mut w);
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
    if bytes.get(..16) != Some(&MAGIC[..]) {
        return Err(ModelFileError::NotAModel { path: path.into() });
    }
    let truncated = || ModelFileError::Truncated { path: path.into(), field: "header", offset: 16, need: HEADER - 16, have: bytes.len() };
    let word = |at: usize| -> Result<u64, ModelFileError> {
        let b: [u8; 8] = bytes.get(at..at + 8).and_then(|s| s.try_into().ok()).ok_or_else(truncated)?;
        Ok(u64::from_le_bytes(b))
    };
    let head = word(16)?;
    let version = (head & 0xffff_ffff) as u32;
    if !(OLDEST_FORMAT_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(ModelFileError::Version { path: path.into(), found: version, supported: FORMAT_VERSION });
    }
    let len = word(24)?;
    let stored = word(32)?;
    let payload = bytes.get(HEADER..).ok_or_else(truncated)?;
    let have = payload.len() as u64;
    if len > have {
        return Err(ModelFileError::Truncated {
            path: path.into(),
            field: "payload",
            offset: HEADER,
            need: len.min(usize::MAX as u64) as usize,
            have: bytes.len(),
        });
    }
    if len < have {
        return Err(ModelFileError::Corrupt { path: path.into(), reason: format!("{} bytes after the end of the model", have - len) });
    }
    let computed = checksum(payload);
    if computed != stored {
        return Err(ModelFileError::Checksum { path: path.into(), stored, computed });
    }
    let mut r = Reader { b: payload, off: 0, path };
    let mut m = HybridModel::default();
    for s in SECTIONS.iter().take(sections_of(version)) {
        (s.read)(&mut r, &mut m)?;
    }
    if r.off != payload.len() {
        return Err(r.corrupt(format!("{} unread bytes at the end of the payload", payload.len() - r.off)));
    }
    for s in &SECTIONS {
        (s.check)(&m).map_err(|reason| r.corrupt(reason))?;
    }
    semantic(&m).map_err(|reason| r.corrupt(reason))?;
    outer::derive(&mut m);
    Ok(m)
}

/// What a built model guarantees beyond index ranges, checked on load so that a crafted file is
/// as safe to use as a freshly built model (the checksum only catches accidents: anyone can
/// write a file with a valid checksum). Finite, physical numbers everywhere (a NaN option or
/// mass would load and print `nan`, or poison the first tick); region ring counts no larger than
/// the builder makes (each region is regrown ring by ring on demand: 255 rings everywhere made a
/// crafted file take a minute); the skin's barycentric weights; voxel owners in range; the core a
/// valid tet mesh (no degenerate or inverted tet: the runtime factorises its stiffness).
fn semantic(m: &HybridModel) -> Result<(), String> {
    options::check(&m.options).map_err(|e| format!("options: {e}"))?;
    if !(m.wall_volume > 0.0 && m.wall_volume.is_finite()) {
        return Err(format!("wall volume {} m^3 must be positive and finite", m.wall_volume));
    }
    let s = &m.stats;
    for (name, t) in [("field", s.field_s), ("core", s.core_s), ("particles", s.particles_s), ("regions", s.regions_s), ("total", s.total_s)] {
        if !(t >= 0.0 && t.is_finite()) {
            return Err(format!("build statistics: {name} time {t} s must be non-negative and finite"));
        }
    }
    // The particle lattice's spacing sizes the shell's volume and the support radius: a negative,
    // zero or NaN one loaded, printed a negative shell volume and failed only at the first tick.
    if !(m.spacing > 0.0 && m.spacing.is_finite()) {
        return Err(format!("particle lattice spacing {} m must be positive and finite", m.spacing));
    }
    if let Some(i) = m.particle_mass.iter().position(|&x| !(x > 0.0 && x.is_finite())) {
        return Err(format!("particle {i}: mass {:?} kg must be positive and finite", m.particle_mass.get(i)));
    }
    if let Some(i) = m.region_rings.iter().position(|&r| r as usize > 2 * options::MAX_RINGS) {
        return Err(format!("region {i}: {:?} rings, more than the builder makes ({})", m.region_rings.get(i), 2 * options::MAX_RINGS));
    }
    for (v, b) in m.skin_bary.iter().enumerate() {
        let sum: f64 = b.iter().sum();
        if !b.iter().all(|x| x.is_finite() && (-1e-6..=1.0 + 1e-6).contains(x)) || (sum - 1.0).abs() > 1e-6 {
            return Err(format!("skin vertex {v}: barycentric weights {b:?} are not in [0, 1] with sum 1"));
        }
    }
    let g = &m.grid;
    if !g.origin.iter().all(|x| x.is_finite()) {
        return Err(format!("voxel grid origin {:?} is not finite", g.origin));
    }
    let nt = m.outer_tris.len() as u32;
    if let Some(v) = m.voxel_owner.iter().position(|&o| o >= nt && o != region_field::VOXEL_OUTSIDE && o != region_field::VOXEL_CORE) {
        return Err(format!("voxel {v}: owner {:?} out of range ({nt} outer triangles)", m.voxel_owner.get(v)));
    }
    if m.outer_tris.is_empty() || m.particles.is_empty() || m.core_tets.is_empty() {
        return Err("empty model: no outer triangles, particles or core tets".into());
    }
    let pts: Vec<[f64; 3]> = m.core_points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let tets: Vec<[i64; 4]> = m.core_tets.iter().map(|t| t.map(|i| i as i64)).collect();
    match crate::mesh::TetMesh::from_arrays(&pts, &tets) {
        Ok((_, w)) if w.is_empty() => Ok(()),
        Ok((_, w)) => Err(format!("FEM core: {} inverted tets (first: {})", w.len(), w.first().map(|x| x.to_string()).unwrap_or_default())),
        Err(e) => Err(format!("FEM core: {e}")),
    }
}

/// Every entry of `v` below `n`, or which is not.
pub(super) fn in_range(what: &str, v: impl IntoIterator<Item = usize>, n: usize) -> Result<(), String> {
    for (i, x) in v.into_iter().enumerate() {
        if x >= n {
            return Err(format!("{what}: entry {i} is {x}, out of range (< {n})"));
        }
    }
    Ok(())
}

/// Every point finite.
pub(super) fn finite(what: &str, v: &[Vec3]) -> Result<(), String> {
    match v.iter().all(|p| p.iter().all(|x| x.is_finite())) {
        true => Ok(()),
        false => Err(format!("non-finite coordinates ({what})")),
    }
}

impl HybridModel {
    /// Save to `path` (see the module docs for the format).
    pub fn save(&self, path: &std::path::Path) -> Result<(), ModelFileError> {
        std::fs::write(path, to_bytes(self)).map_err(|e| ModelFileError::Io { path: path.display().to_string(), reason: e.to_string() })
    }

    /// Load from `path`.
    pub fn load(path: &std::path::Path) -> Result<HybridModel, ModelFileError> {
        let name = path.display().to_string();
        let io = |e: std::io::Error| ModelFileError::Io { path: name.clone(), reason: e.to_string() };
        // A FIFO or a device would block the read forever (or never end): regular files only.
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            let kind = if meta.is_dir() { "a directory" } else { "not a regular file (a FIFO, socket or device?)" };
            return Err(ModelFileError::Io { path: name, reason: format!("{kind}: a model file must be a regular file") });
        }
        crate::limits::check("model file", meta.len() as f64, 1.0).map_err(|source| ModelFileError::Limit { path: name.clone(), source })?;
        let bytes = std::fs::read(path).map_err(io)?;
        from_bytes(&bytes, &name)
    }
}
