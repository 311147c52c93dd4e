//! Record and replay: an interaction's device inputs (and what the loop rendered from them) with
//! the identity of the model and of the loop's parameters, in one binary file.
//!
//! Replaying the inputs through a loop with the same model and parameters gives bit-identical
//! forces and positions: every tick is a function of the inputs and the tick count only (the
//! simulation steps the nominal `dt`, the ramp counts ticks, not seconds). A watchdog trip (a
//! physics stall, which depends on the machine's timing) breaks this, and is in the file's fault
//! count.
//!
//! A multirate recording ([`crate::multirate`]) also holds what the physics thread consumed (the
//! proxy positions it ticked with, in order) and which physics tick's model each servo tick
//! rendered from: the physics replays from the first, the servo from the second, each bit for
//! bit, whatever the machine's timing was.
//!
//! # File format, version 2 (little-endian; version 1, without the fields marked v2, loads)
//! ```text
//! magic     8 bytes  "PALPREC\0"
//! version   u32      2
//! rate_hz   f64      the loop's (servo's) rate
//! digest    u64      the simulation's Identity::digest
//! desc_len  u32, desc  UTF-8, the Identity's description
//! coupling  3 x f64  stiffness [N/m], damping [N s/m], proxy mass [kg]
//! safety    4 x f64  max force [N], max rate [N/s], ramp [s], stall timeout [s]
//! silence   f64      (v2) the safety's device silence [s]
//! physics   f64      (v2) the physics thread's rate [Hz]; 0: the single-rate loop
//! faults    u64      faults during the recording
//! n         u64      ticks
//! n records, 144 bytes each:
//!   position 3 x f64 [m], orientation 4 x f64 (w, x, y, z), buttons u32, pad u32,
//!   has_input u8 (0: the device gave no sample that tick; the servo held the last),
//!   stalled u8 (1: the watchdog tripped in this tick; 0 in files written before 2026-12-06,
//!   where it was padding), 6 pad bytes,
//!   force 3 x f64 [N] (sent), tool 3 x f64 [m] (the proxy), tissue 3 x f64 [N]
//! (v2) m    u64      model ticks (n for a multirate recording, else 0), then m x u64
//! (v2) p    u64      physics targets, then p x 3 x f64 [m]
//! ```

use std::io::{Read, Write};

use palpate_core::Vec3;

use crate::coupling::CouplingParams;
use crate::device::DeviceInput;
use crate::physics::Identity;
use crate::safety::SafetyParams;

const MAGIC: &[u8; 8] = b"PALPREC\0";
/// The format's version (the previous one still loads).
pub const VERSION: u32 = 2;
const RECORD_BYTES: usize = 144;

/// One recorded tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickRecord {
    pub input: DeviceInput,
    /// Did the device give a sample this tick?
    pub has_input: bool,
    /// Did the watchdog trip in this tick (the physics stalled: an event of the machine's clock,
    /// which a replay cannot reproduce)? Recordings made before 2026-12-06 say false.
    pub stalled: bool,
    pub force: Vec3,
    pub tool: Vec3,
    pub tissue: Vec3,
}

/// A recorded interaction.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    pub rate_hz: f64,
    pub identity: Identity,
    pub coupling: CouplingParams,
    pub safety: SafetyParams,
    pub faults: u64,
    pub ticks: Vec<TickRecord>,
    /// The physics thread's rate \[Hz\] of a multirate loop (`None`: single-rate).
    pub physics_rate_hz: Option<f64>,
    /// Multirate: the physics tick whose model each servo tick rendered from (0: none yet).
    pub model_ticks: Vec<u64>,
    /// Multirate: the tool targets the physics ticked with, in order \[m\].
    pub targets: Vec<Vec3>,
}

/// A file that is not a recording of this version (or is damaged).
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{path}: {reason}")]
    Format { path: String, reason: String },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
    /// A file larger than the memory budget (`palpate_core::limits`), refused before reading.
    #[error("{path}: {source}")]
    Limit { path: String, source: palpate_core::LimitError },
}

impl Recording {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(128 + self.identity.description.len() + RECORD_BYTES * self.ticks.len());
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&self.rate_hz.to_le_bytes());
        b.extend_from_slice(&self.identity.digest.to_le_bytes());
        b.extend_from_slice(&(self.identity.description.len() as u32).to_le_bytes());
        b.extend_from_slice(self.identity.description.as_bytes());
        let c = &self.coupling;
        let s = &self.safety;
        for v in [
            c.stiffness,
            c.damping,
            c.proxy_mass,
            s.max_force,
            s.max_rate,
            s.ramp,
            s.stall_timeout,
            s.silence,
            self.physics_rate_hz.unwrap_or(0.0),
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.faults.to_le_bytes());
        b.extend_from_slice(&(self.ticks.len() as u64).to_le_bytes());
        for t in &self.ticks {
            let f = |b: &mut Vec<u8>, v: f64| b.extend_from_slice(&v.to_le_bytes());
            t.input.position.iter().for_each(|&v| f(&mut b, v));
            t.input.orientation.iter().for_each(|&v| f(&mut b, v));
            b.extend_from_slice(&t.input.buttons.to_le_bytes());
            b.extend_from_slice(&[0; 4]);
            b.push(t.has_input as u8);
            b.push(t.stalled as u8);
            b.extend_from_slice(&[0; 6]);
            for v in [&t.force, &t.tool, &t.tissue] {
                v.iter().for_each(|&x| f(&mut b, x));
            }
        }
        b.extend_from_slice(&(self.model_ticks.len() as u64).to_le_bytes());
        self.model_ticks.iter().for_each(|t| b.extend_from_slice(&t.to_le_bytes()));
        b.extend_from_slice(&(self.targets.len() as u64).to_le_bytes());
        self.targets.iter().flat_map(|t| t.iter()).for_each(|v| b.extend_from_slice(&v.to_le_bytes()));
        b
    }

    pub fn from_bytes(bytes: &[u8], path: &str) -> Result<Recording, RecordError> {
        let bad = |reason: String| RecordError::Format { path: path.to_string(), reason };
        let mut r = Reader { b: bytes, at: 0 };
        if r.take(8).ok_or_else(|| bad("shorter than the header".into()))? != MAGIC {
            return Err(bad("not a palpate recording (bad magic)".into()));
        }
        let short = || bad("truncated header".into());
        let version = r.u32().ok_or_else(short)?;
        if !(1..=VERSION).contains(&version) {
            return Err(bad(format!("recording version {version}, this build reads versions 1 to {VERSION}")));
        }
        let rate_hz = r.f64().ok_or_else(short)?;
        let digest = r.u64().ok_or_else(short)?;
        let n = r.u32().ok_or_else(short)? as usize;
        let description = String::from_utf8(r.take(n).ok_or_else(short)?.to_vec()).map_err(|_| bad("description is not UTF-8".into()))?;
        let mut v = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, SafetyParams::default().silence, 0.0];
        for x in &mut v[..if version == 1 { 7 } else { 9 }] {
            *x = r.f64().ok_or_else(short)?;
        }
        let faults = r.u64().ok_or_else(short)?;
        let n = r.u64().ok_or_else(short)?;
        let rest = bytes.len() - r.at;
        let fits = match n.checked_mul(RECORD_BYTES as u64) {
            Some(need) if version == 1 => need == rest as u64,
            Some(need) => need <= rest as u64,
            None => false,
        };
        if !fits {
            return Err(bad(format!("{n} ticks need {} bytes after the header, the file has {rest}", n.saturating_mul(RECORD_BYTES as u64))));
        }
        let mut ticks = Vec::with_capacity(n as usize);
        for _ in 0..n {
            let mut f = || r.f64().unwrap();
            let position = Vec3::new(f(), f(), f());
            let orientation = [f(), f(), f(), f()];
            let buttons = r.u32().unwrap();
            r.take(4);
            let flags = r.take(8).unwrap();
            let (has_input, stalled) = (flags[0] != 0, flags[1] != 0);
            let mut f = || r.f64().unwrap();
            let force = Vec3::new(f(), f(), f());
            let tool = Vec3::new(f(), f(), f());
            let tissue = Vec3::new(f(), f(), f());
            ticks.push(TickRecord { input: DeviceInput { position, orientation, buttons }, has_input, stalled, force, tool, tissue });
        }
        let (mut model_ticks, mut targets) = (Vec::new(), Vec::new());
        if version >= 2 {
            let short = || bad("truncated multirate section".into());
            let m = r.u64().ok_or_else(short)?;
            if m != 0 && m != n {
                return Err(bad(format!("{m} model ticks for {n} ticks")));
            }
            let need = m.checked_mul(8).ok_or_else(short)?;
            if need > (bytes.len() - r.at) as u64 {
                return Err(short());
            }
            model_ticks = (0..m).map(|_| r.u64().unwrap()).collect();
            let p = r.u64().ok_or_else(short)?;
            if p.checked_mul(24) != Some((bytes.len() - r.at) as u64) {
                return Err(bad(format!("{p} physics targets need {} bytes, the file has {}", p.saturating_mul(24), bytes.len() - r.at)));
            }
            targets = (0..p).map(|_| Vec3::new(r.f64().unwrap(), r.f64().unwrap(), r.f64().unwrap())).collect();
        }
        let safety = SafetyParams { max_force: v[3], max_rate: v[4], ramp: v[5], stall_timeout: v[6], silence: v[7] };
        let physics_rate_hz = (v[8] > 0.0).then_some(v[8]);
        Ok(Recording {
            rate_hz,
            identity: Identity { digest, description },
            coupling: CouplingParams::new(v[0], v[1], v[2]),
            safety,
            faults,
            ticks,
            physics_rate_hz,
            model_ticks,
            targets,
        })
    }

    pub fn save(&self, path: &std::path::Path) -> Result<(), RecordError> {
        let io = |source| RecordError::Io { path: path.display().to_string(), source };
        let mut f = std::fs::File::create(path).map_err(io)?;
        f.write_all(&self.to_bytes()).map_err(io)
    }

    /// Load from `path`: a regular file within the memory budget (`PALPATE_MAX_MEMORY`). A FIFO,
    /// socket or device is refused before it is opened (the read would block for ever, or never
    /// end), and so is a file whose bytes and ticks would not fit the budget (its bytes, then
    /// its ticks as records: about twice its size) before anything is read.
    pub fn load(path: &std::path::Path) -> Result<Recording, RecordError> {
        let name = path.display().to_string();
        let io = |source| RecordError::Io { path: name.clone(), source };
        let meta = std::fs::metadata(path).map_err(io)?;
        if !meta.is_file() {
            let kind = if meta.is_dir() { "a directory" } else { "not a regular file (a FIFO, socket or device?)" };
            return Err(io(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{kind}: a recording must be a regular file"))));
        }
        palpate_core::limits::check("recording", meta.len() as f64, 2.0).map_err(|source| RecordError::Limit { path: name.clone(), source })?;
        let mut b = Vec::new();
        // At most the size checked above (the file may grow while it is read).
        std::fs::File::open(path).map_err(io)?.take(meta.len()).read_to_end(&mut b).map_err(io)?;
        Recording::from_bytes(&b, &name)
    }
}

/// The first tick where two recordings' forces or tool positions differ in any bit (`None`:
/// identical over the shorter; the lengths are the caller's to compare).
pub fn compare(a: &Recording, b: &Recording) -> Option<usize> {
    let bits = |v: &Vec3| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
    a.ticks
        .iter()
        .zip(&b.ticks)
        .position(|(x, y)| bits(&x.force) != bits(&y.force) || bits(&x.tool) != bits(&y.tool) || bits(&x.input.position) != bits(&y.input.position))
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        self.take(4).map(|s| u32::from_le_bytes(s.try_into().unwrap()))
    }
    fn u64(&mut self) -> Option<u64> {
        self.take(8).map(|s| u64::from_le_bytes(s.try_into().unwrap()))
    }
    fn f64(&mut self) -> Option<f64> {
        self.take(8).map(|s| f64::from_le_bytes(s.try_into().unwrap()))
    }
}
