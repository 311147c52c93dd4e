//! The memory budget: every size that comes from input (node and element counts, voxel grids,
//! particle and neighbour counts, step counts, decompressed lengths) is checked here *before* the
//! memory is taken. Rust aborts the whole process when an allocation fails (there is nothing a
//! Python caller could catch), so a file claiming 1e8 nodes or a support radius of 10 um must be
//! refused while it is still only a number.
//!
//! The budget ([`budget`]) is read at every check (checks sit outside hot loops; a check costs a
//! few small file reads, ~75 us measured on the project's 2-core machine):
//! - `PALPATE_MAX_MEMORY` (bytes, or with a suffix `K`, `M`, `G`, `T`: powers of 1024) when set
//!   and readable;
//! - else, on Linux, [`MARGIN`] times the smallest of what the process may still use: the
//!   address-space limit (`RLIMIT_AS`, from `/proc/self/limits`) less what is already mapped
//!   (`VmSize` in `/proc/self/status`), the memory limit of the process's cgroup (v2
//!   `memory.max`, v1 `memory.limit_in_bytes`, the smallest along its path) and `MemAvailable`
//!   (`/proc/meminfo`). Plain file reads: no libc, no new dependency;
//! - else (another system, or nothing readable) [`DEFAULT_MAX_MEMORY`].

use crate::error::LimitError;

/// The budget when no limit of the machine can be read (8 GiB): a third of the project's 24 GiB
/// machines, and 2x the largest structure of the shipped models (the Rodero build's voxel grid
/// is well under 1 GiB).
pub const DEFAULT_MAX_MEMORY: u64 = 8 << 30;

/// The fraction of the smallest limit that one request may take. One half: the checked
/// structure is rarely alone: its builder keeps the input (or the compressed bytes) while it
/// fills it, a conversion to or from numpy copies it once, and the process already holds the
/// interpreter, the model and its other arrays; a request of half the headroom leaves the other
/// half for those. A quarter would refuse models that fit (the Rodero build on a 4 GiB
/// container); the whole headroom would let the copy be the allocation that fails (an abort).
pub const MARGIN: f64 = 0.5;

// No cap above the machine's limits: the old fixed 8 GiB stood in for not knowing the machine;
// now that it is read, a 64 GiB workstation may build what fits in 32 GiB without setting
// PALPATE_MAX_MEMORY, and a 2 GiB container is refused at 1 GiB rather than killed at 2.
/// The largest external force palpate takes as one node's force or one load's total \[N\]:
/// 1e6 N, the weight of 100 t. Why this value: soft tissue tears at tens of newtons and a haptic
/// device renders at most tens (the device classes' ratings in palpate-haptics), so no load of
/// this domain comes within four orders of it, while a force over it is a unit or data mistake
/// (1e300 was taken without a word). And it keeps the arithmetic of a step well inside f64:
/// squared norms (residuals, line searches) stay under 1e12 N^2 where 1e300 N overflowed to inf.
pub const MAX_FORCE_N: f64 = 1e6;

/// |f| \[N\] for a message, scaled by the largest component: the plain norm of (0, 0, 1e300)
/// squares to inf.
pub fn force_magnitude(f: &crate::Vec3) -> f64 {
    let big = f.amax();
    if big > 0.0 && big.is_finite() {
        big * (f / big).norm()
    } else {
        big
    }
}

/// Is `f` finite with |f| <= [`MAX_FORCE_N`]?
pub fn force_in_bound(f: &crate::Vec3) -> bool {
    f.x.is_finite() && f.y.is_finite() && f.z.is_finite() && f.norm() <= MAX_FORCE_N
}

/// The environment variable that sets the budget.
pub const ENV: &str = "PALPATE_MAX_MEMORY";

/// The budget of one request and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// Bytes one input-derived structure may take.
    pub bytes: u64,
    /// Where the number came from, for messages: e.g. "the cgroup's memory limit (2.0 GiB) x 0.5".
    pub source: String,
}

/// A size such as `"8G"`, `"512M"`, `"1e9"` or `"1073741824"` in bytes; `None` if unreadable or
/// not positive.
pub fn parse_size(s: &str) -> Option<u64> {
    // "2GiB", "2GB", "2G" alike: drop a trailing B, then a trailing i, then read the unit.
    let s = s.trim();
    let s = s.strip_suffix(['B', 'b']).unwrap_or(s);
    let s = s.strip_suffix(['i', 'I']).unwrap_or(s);
    let (num, mul) = match s.chars().last()?.to_ascii_uppercase() {
        'K' => (&s[..s.len() - 1], 1u64 << 10),
        'M' => (&s[..s.len() - 1], 1 << 20),
        'G' => (&s[..s.len() - 1], 1 << 30),
        'T' => (&s[..s.len() - 1], 1 << 40),
        _ => (s, 1),
    };
    let v: f64 = num.trim().parse().ok()?;
    let bytes = v * mul as f64;
    (1.0..1.8e19).contains(&bytes).then_some(bytes as u64)
}

/// The budget in bytes ([`budget`]`().bytes`).
pub fn max_memory() -> u64 {
    budget().bytes
}

/// The budget of one request now, and its source: `PALPATE_MAX_MEMORY`, else the machine's
/// limits x [`MARGIN`], else [`DEFAULT_MAX_MEMORY`].
pub fn budget() -> Budget {
    if let Ok(s) = std::env::var(ENV) {
        if let Some(bytes) = parse_size(&s) {
            return Budget { bytes, source: format!("{ENV}={}", s.trim()) };
        }
    }
    let read = |p: &str| std::fs::read_to_string(p).ok();
    budget_from(&SystemFiles {
        limits: read("/proc/self/limits"),
        status: read("/proc/self/status"),
        meminfo: read("/proc/meminfo"),
        cgroup_limits: cgroup_limits(read("/proc/self/cgroup").as_deref(), &read),
    })
}

/// The texts [`budget`] reads (each `None` when unreadable), separated for the tests.
#[derive(Debug, Default, Clone)]
pub struct SystemFiles {
    /// `/proc/self/limits`.
    pub limits: Option<String>,
    /// `/proc/self/status`.
    pub status: Option<String>,
    /// `/proc/meminfo`.
    pub meminfo: Option<String>,
    /// The texts of the cgroup limit files found (`memory.max` / `memory.limit_in_bytes`).
    pub cgroup_limits: Vec<String>,
}

/// The budget from the files' texts: the smallest readable limit x [`MARGIN`], or the default.
pub fn budget_from(f: &SystemFiles) -> Budget {
    let mut best: Option<(u64, String)> = None;
    let mut consider = |bytes: u64, what: String| {
        if best.as_ref().is_none_or(|(b, _)| bytes < *b) {
            best = Some((bytes, what));
        }
    };
    if let Some(limit) = f.limits.as_deref().and_then(parse_rlimit_as) {
        let mapped = f.status.as_deref().and_then(parse_vm_size).unwrap_or(0);
        let left = limit.saturating_sub(mapped);
        consider(left, format!("the address-space limit RLIMIT_AS ({}) less the {} already mapped", human_bytes(limit as f64), human_bytes(mapped as f64)));
    }
    if let Some(limit) = f.cgroup_limits.iter().filter_map(|t| parse_cgroup_limit(t)).min() {
        consider(limit, format!("the cgroup's memory limit ({})", human_bytes(limit as f64)));
    }
    if let Some(avail) = f.meminfo.as_deref().and_then(parse_mem_available) {
        consider(avail, format!("the memory available, MemAvailable ({})", human_bytes(avail as f64)));
    }
    match best {
        // At least 1 byte: a process at its limit refuses everything rather than divides by zero.
        Some((bytes, what)) => Budget { bytes: ((bytes as f64 * MARGIN) as u64).max(1), source: format!("{what} x {MARGIN}") },
        None => Budget { bytes: DEFAULT_MAX_MEMORY, source: "the default: no memory limit of this system could be read".to_string() },
    }
}

/// The soft `Max address space` of `/proc/self/limits` in bytes; `None` when unlimited or
/// unreadable. The line is `Max address space  <soft> <hard> bytes`.
pub fn parse_rlimit_as(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    let soft = line["Max address space".len()..].split_whitespace().next()?;
    if soft == "unlimited" {
        return None;
    }
    soft.parse().ok()
}

/// `VmSize` of `/proc/self/status` in bytes (the line is `VmSize:  123456 kB`).
pub fn parse_vm_size(text: &str) -> Option<u64> {
    kib_field(text, "VmSize:")
}

/// `MemAvailable` of `/proc/meminfo` in bytes (the line is `MemAvailable:  123456 kB`).
pub fn parse_mem_available(text: &str) -> Option<u64> {
    kib_field(text, "MemAvailable:")
}

fn kib_field(text: &str, key: &str) -> Option<u64> {
    let rest = text.lines().find_map(|l| l.strip_prefix(key))?;
    let mut it = rest.split_whitespace();
    let v: u64 = it.next()?.parse().ok()?;
    match it.next() {
        Some("kB") => v.checked_mul(1024),
        _ => None,
    }
}

/// A cgroup limit file's text in bytes: v2 `memory.max` (`max` = none) or v1
/// `memory.limit_in_bytes` (no limit is written as ~2^63 rounded to a page: anything from 2^60
/// up is none).
pub fn parse_cgroup_limit(text: &str) -> Option<u64> {
    let t = text.trim();
    if t == "max" {
        return None;
    }
    let v: u64 = t.parse().ok()?;
    (v > 0 && v < 1 << 60).then_some(v)
}

/// The cgroup memory-limit files of the process's cgroup and of each ancestor (a parent's
/// limit binds its children too), read with `read`. `cgroup` is `/proc/self/cgroup`: the v2 line
/// `0::/path`, a v1 line `N:memory:/path` (or `N:...,memory,...:/path`). In a container the
/// path may name the host's hierarchy while `/sys/fs/cgroup` is the container's own: then the
/// path does not exist and the mount's root (the container's cgroup) is read.
pub fn cgroup_limits(cgroup: Option<&str>, read: &dyn Fn(&str) -> Option<String>) -> Vec<String> {
    let mut out = Vec::new();
    let Some(cgroup) = cgroup else { return out };
    for line in cgroup.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(_id), Some(ctrl), Some(path)) = (parts.next(), parts.next(), parts.next()) else {
            continue;
        };
        let (base, file) = if ctrl.is_empty() {
            ("/sys/fs/cgroup", "memory.max")
        } else if ctrl.split(',').any(|c| c == "memory") {
            ("/sys/fs/cgroup/memory", "memory.limit_in_bytes")
        } else {
            continue;
        };
        // The path and its ancestors, the root ("") last; no "..": a path is the kernel's.
        let path = path.trim();
        if !path.starts_with('/') || path.split('/').any(|c| c == "..") {
            continue;
        }
        let mut dir = path.trim_end_matches('/').to_string();
        loop {
            if let Some(t) = read(&format!("{base}{dir}/{file}")) {
                out.push(t);
            }
            match dir.rfind('/') {
                Some(k) => dir.truncate(k),
                None => break,
            }
            if dir.is_empty() {
                if let Some(t) = read(&format!("{base}/{file}")) {
                    out.push(t);
                }
                break;
            }
        }
    }
    out
}

/// Refuse `count` items of `bytes_each` bytes for `what` when they exceed the budget. `count` is
/// an `f64` so that a product of grid dimensions cannot overflow before it is compared (a NaN or
/// infinite count is refused too).
pub fn check(what: &str, count: f64, bytes_each: f64) -> Result<(), LimitError> {
    let need = count * bytes_each;
    // Cheap refusals first: a NaN or negative need reads no file.
    if !(need.is_finite() && need >= 0.0) {
        let b = budget();
        return Err(LimitError { what: what.to_string(), count, bytes: need, budget: b.bytes, budget_source: b.source });
    }
    let b = budget();
    if need <= b.bytes as f64 {
        Ok(())
    } else {
        Err(LimitError { what: what.to_string(), count, bytes: need, budget: b.bytes, budget_source: b.source })
    }
}

/// [`check`] of a grid of `dims` cells (each possibly huge or non-finite).
pub fn check_grid(what: &str, dims: [f64; 3], bytes_each: f64) -> Result<(), LimitError> {
    check(what, dims[0] * dims[1] * dims[2], bytes_each)
}

/// `b` bytes for a message: `46.7 GiB`.
pub fn human_bytes(b: f64) -> String {
    if !b.is_finite() {
        return format!("{b}");
    }
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut v = b;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{v:.0} B")
    } else {
        format!("{v:.1} {}", units[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("1G"), Some(1 << 30));
        assert_eq!(parse_size("512M"), Some(512 << 20));
        assert_eq!(parse_size("2GiB"), Some(2 << 30));
        assert_eq!(parse_size("1e9"), Some(1_000_000_000));
        assert_eq!(parse_size("-1"), None);
        assert_eq!(parse_size("lots"), None);
        assert_eq!(parse_size(""), None);
    }

    #[test]
    fn over_budget_is_refused_with_the_numbers() {
        assert!(check("x", 10.0, 8.0).is_ok());
        let e = check("voxel grid", 1e12, 2.0).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("voxel grid") && msg.contains("PALPATE_MAX_MEMORY"), "{msg}");
        // The message says where the budget came from (the limit, or the variable).
        assert!(!e.budget_source.is_empty() && msg.contains(&e.budget_source), "{msg}");
        assert!(check("x", f64::INFINITY, 1.0).is_err());
        assert!(check("x", f64::NAN, 1.0).is_err());
    }

    // Sample texts of each file, as the kernel writes them, and garbage.
    const LIMITS: &str = "Limit                     Soft Limit           Hard Limit           Units     \n\
Max cpu time              unlimited            unlimited            seconds   \n\
Max address space         2147483648           unlimited            bytes     \n\
Max open files            1024                 1048576              files     \n";
    const MEMINFO: &str = "MemTotal:       24567000 kB\nMemFree:         7000000 kB\nMemAvailable:   22671028 kB\nBuffers:          100 kB\n";
    const STATUS: &str = "Name:\tpython3\nVmPeak:\t  600000 kB\nVmSize:\t  524288 kB\nVmRSS:\t   80000 kB\n";

    #[test]
    fn proc_files_parse() {
        assert_eq!(parse_rlimit_as(LIMITS), Some(2 << 30));
        assert_eq!(parse_rlimit_as(&LIMITS.replace("2147483648", "unlimited")), None);
        assert_eq!(parse_rlimit_as("Max address space         lots  unlimited bytes"), None);
        assert_eq!(parse_rlimit_as("Max address space"), None);
        assert_eq!(parse_rlimit_as(""), None);
        assert_eq!(parse_rlimit_as("\u{0}\u{ff}garbage\n\n"), None);
        assert_eq!(parse_mem_available(MEMINFO), Some(22671028 * 1024));
        assert_eq!(parse_mem_available("MemAvailable: 12 MB\n"), None); // the kernel writes kB only
        assert_eq!(parse_mem_available("MemAvailable:\n"), None);
        assert_eq!(parse_mem_available("MemAvailable: 99999999999999999999 kB\n"), None);
        assert_eq!(parse_mem_available("MemFree: 5 kB\n"), None);
        assert_eq!(parse_vm_size(STATUS), Some(512 << 20));
        assert_eq!(parse_vm_size("VmSize: -3 kB"), None);
    }

    #[test]
    fn cgroup_files_parse() {
        assert_eq!(parse_cgroup_limit("max\n"), None);
        assert_eq!(parse_cgroup_limit("4294967296\n"), Some(4 << 30));
        assert_eq!(parse_cgroup_limit("9223372036854771712\n"), None); // v1's "no limit"
        assert_eq!(parse_cgroup_limit("0"), None);
        assert_eq!(parse_cgroup_limit("-1"), None);
        assert_eq!(parse_cgroup_limit("garbage"), None);
        assert_eq!(parse_cgroup_limit(""), None);
    }

    #[test]
    fn cgroup_paths_follow_the_process_and_its_ancestors() {
        use std::cell::RefCell;
        let asked = RefCell::new(Vec::new());
        let read = |p: &str| -> Option<String> {
            asked.borrow_mut().push(p.to_string());
            match p {
                "/sys/fs/cgroup/user.slice/app.scope/memory.max" => Some("max\n".into()),
                "/sys/fs/cgroup/user.slice/memory.max" => Some("3221225472\n".into()),
                "/sys/fs/cgroup/memory/memory.limit_in_bytes" => Some("9223372036854771712\n".into()),
                _ => None,
            }
        };
        let v2 = cgroup_limits(Some("0::/user.slice/app.scope\n"), &read);
        assert_eq!(v2, vec!["max\n".to_string(), "3221225472\n".to_string()]);
        assert_eq!(v2.iter().filter_map(|t| parse_cgroup_limit(t)).min(), Some(3 << 30));
        // v1, as in a container whose /proc/self/cgroup names the host's path: the mount's root.
        let v1 = cgroup_limits(Some("9:name=systemd:/\n4:memory:/process_api/73e0\n1:cpu:/\n"), &read);
        assert_eq!(v1, vec!["9223372036854771712\n".to_string()]);
        assert!(asked.borrow().contains(&"/sys/fs/cgroup/memory/process_api/73e0/memory.limit_in_bytes".to_string()));
        // Garbage and escapes read nothing outside /sys/fs/cgroup.
        asked.borrow_mut().clear();
        assert!(cgroup_limits(Some("garbage\n0::relative\n0::/../../etc\n\u{0}:memory\n"), &read).is_empty());
        assert!(asked.borrow().iter().all(|p| p.starts_with("/sys/fs/cgroup/") && !p.contains("..")));
        assert!(cgroup_limits(None, &read).is_empty());
    }

    #[test]
    fn the_smallest_limit_times_the_margin_is_the_budget() {
        let gib = 1u64 << 30;
        // Only MemAvailable.
        let b = budget_from(&SystemFiles { meminfo: Some(MEMINFO.into()), ..Default::default() });
        assert_eq!(b.bytes, (22671028.0 * 1024.0 * MARGIN) as u64);
        assert!(b.source.contains("MemAvailable"), "{}", b.source);
        // RLIMIT_AS 2 GiB, 0.5 GiB mapped: 1.5 GiB left x 0.5.
        let b = budget_from(&SystemFiles { limits: Some(LIMITS.into()), status: Some(STATUS.into()), meminfo: Some(MEMINFO.into()), ..Default::default() });
        assert_eq!(b.bytes, 3 * gib / 4);
        assert!(b.source.contains("RLIMIT_AS") && b.source.contains("x 0.5"), "{}", b.source);
        // A cgroup of 1 GiB below both.
        let b = budget_from(&SystemFiles {
            limits: Some(LIMITS.into()),
            status: Some(STATUS.into()),
            meminfo: Some(MEMINFO.into()),
            cgroup_limits: vec!["max".into(), "1073741824".into()],
        });
        assert_eq!(b.bytes, gib / 2);
        assert!(b.source.contains("cgroup"), "{}", b.source);
        // Nothing readable, or only garbage: the old default.
        let none = budget_from(&SystemFiles::default());
        assert_eq!(none.bytes, DEFAULT_MAX_MEMORY);
        assert!(none.source.contains("default"));
        let junk = budget_from(&SystemFiles {
            limits: Some("junk".into()),
            status: Some("junk".into()),
            meminfo: Some("junk".into()),
            cgroup_limits: vec!["junk".into()],
        });
        assert_eq!(junk.bytes, DEFAULT_MAX_MEMORY);
        // Mapped beyond the limit: a budget of 1 byte, not an underflow.
        let full = budget_from(&SystemFiles { limits: Some(LIMITS.into()), status: Some("VmSize: 4194304 kB\n".into()), ..Default::default() });
        assert_eq!(full.bytes, 1);
    }

    #[test]
    fn this_machine_has_a_budget_with_a_source() {
        // Whatever the machine: positive, named; on Linux read from /proc (MemAvailable at least).
        let b = budget();
        assert!(b.bytes > 0 && !b.source.is_empty(), "{b:?}");
        if cfg!(target_os = "linux") && std::env::var(ENV).is_err() {
            assert!(!b.source.contains("default"), "{b:?}");
        }
    }
}
