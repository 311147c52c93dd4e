//! The memory budget: every size that comes from input (node and element counts, voxel grids,
//! particle and neighbour counts, step counts, decompressed lengths) is checked here *before* the
//! memory is taken. Rust aborts the whole process when an allocation fails (there is nothing a
//! Python caller could catch), so a file claiming 1e8 nodes or a support radius of 10 um must be
//! refused while it is still only a number.
//!
//! The budget is `PALPATE_MAX_MEMORY` (bytes, or with a suffix `K`, `M`, `G`, `T`: powers of
//! 1024), read at every check (checks sit outside hot loops), else [`DEFAULT_MAX_MEMORY`].

use crate::error::LimitError;

/// The default budget of one allocation request (8 GiB): a third of the project's 24 GiB
/// machines, and 2x the largest structure of the shipped models (the Rodero build's voxel grid
/// is well under 1 GiB).
pub const DEFAULT_MAX_MEMORY: u64 = 8 << 30;

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
    if big > 0.0 && big.is_finite() { big * (f / big).norm() } else { big }
}

/// Is `f` finite with |f| <= [`MAX_FORCE_N`]?
pub fn force_in_bound(f: &crate::Vec3) -> bool {
    f.x.is_finite() && f.y.is_finite() && f.z.is_finite() && f.norm() <= MAX_FORCE_N
}

/// The environment variable that sets the budget.
pub const ENV: &str = "PALPATE_MAX_MEMORY";

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

/// The budget in bytes: `PALPATE_MAX_MEMORY` when set and readable, else the default.
pub fn max_memory() -> u64 {
    std::env::var(ENV).ok().and_then(|s| parse_size(&s)).unwrap_or(DEFAULT_MAX_MEMORY)
}

/// Refuse `count` items of `bytes_each` bytes for `what` when they exceed the budget. `count` is
/// an `f64` so that a product of grid dimensions cannot overflow before it is compared (a NaN or
/// infinite count is refused too).
pub fn check(what: &str, count: f64, bytes_each: f64) -> Result<(), LimitError> {
    let need = count * bytes_each;
    let budget = max_memory();
    if need.is_finite() && need >= 0.0 && need <= budget as f64 {
        Ok(())
    } else {
        Err(LimitError { what: what.to_string(), count, bytes: need, budget })
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
    if u == 0 { format!("{v:.0} B") } else { format!("{v:.1} {}", units[u]) }
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
        assert!(check("x", f64::INFINITY, 1.0).is_err());
        assert!(check("x", f64::NAN, 1.0).is_err());
    }
}
