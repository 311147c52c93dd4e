//! Plausible scales for a hybrid simulation's parameters: a value far outside what an organ and a
//! surgical tool have was most likely given in the wrong unit.
//!
//! palpate is SI throughout (m, Pa, kg/m^3, s), and a unit mistake passes every validity check: a
//! Young's modulus typed in kPa (`30` for 30 kPa) is a positive, finite, very soft material; a
//! tool radius in mm (`5` for 5 mm) a 5 m sphere; a tool target in mm a point metres away (zero
//! force, or the force limit once the tool is dragged toward it). These checks name the value,
//! the range it left and the unit that would put it inside. They are warnings by default (the
//! bindings issue them as `palpate.UnitWarning`) and errors on request (`strict_units`).
//!
//! Ranges: soft tissues' Young's moduli span about 100 Pa (brain, fat) to 10 MPa (tendon,
//! cartilage in compression); myocardium is 10-100 kPa. Surgical and palpation tools are
//! under 5 cm across. Organs are under 1 m; a target farther than that from the organ's
//! bounding box is not a hand's reach.

use crate::material::Material;
use crate::math::Vec3;

/// Young's moduli of soft tissue \[Pa\]: 100 Pa to 10 MPa.
pub const TISSUE_YOUNG_PA: (f64, f64) = (100.0, 1.0e7);
/// The largest plausible tool radius \[m\]: 5 cm.
pub const TOOL_RADIUS_MAX_M: f64 = 0.05;
/// The farthest plausible tool target from the organ's bounding box \[m\]: 1 m.
pub const TOOL_REACH_M: f64 = 1.0;

/// The factor of 1000 (a k or m prefix) that would bring `value` inside `[lo, hi]`, as
/// `(factor, prefix)`: `value * factor` is inside.
fn thousand(value: f64, lo: f64, hi: f64) -> Option<(f64, &'static str)> {
    [(1e3, "k"), (1e6, "M"), (1e-3, "m")].into_iter().find(|&(f, _)| (lo..=hi).contains(&(value * f)))
}

/// `x` to 4 significant digits, without trailing zeros (a Young's modulus from Lame constants
/// comes back as 29999.999999996): `0.052`, `30000`, `1.235e-05` below 1e-4.
pub fn sig(x: f64) -> String {
    if x != 0.0 && x.is_finite() && x.abs() < 1e-4 {
        return format!("{x:.3e}");
    }
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let decimals = (3 - x.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Messages for a material's Young's modulus outside [`TISSUE_YOUNG_PA`] and a tool radius over
/// [`TOOL_RADIUS_MAX_M`] (none when both are plausible; non-finite values are left to the
/// parameters' own validation).
pub fn parameter_warnings(material: &Material, tool_radius: f64) -> Vec<String> {
    let mut out = Vec::new();
    let e = material.young();
    let (lo, hi) = TISSUE_YOUNG_PA;
    if e.is_finite() && !(lo..=hi).contains(&e) {
        let hint = match thousand(e, lo, hi) {
            Some((f, p)) if f > 1.0 => format!("; typed in {p}Pa? {} {p}Pa is {} Pa", sig(e), sig(e * f)),
            _ => String::new(),
        };
        out.push(format!("Young's modulus {} Pa is outside soft tissue's 100 Pa to 10 MPa (myocardium: 10-100 kPa){hint}", sig(e)));
    }
    if tool_radius.is_finite() && tool_radius > TOOL_RADIUS_MAX_M {
        out.push(format!(
            "tool radius {} m is over 5 cm: lengths are in metres (typed in mm? {} mm is {} m)",
            sig(tool_radius),
            sig(tool_radius),
            sig(tool_radius * 1e-3)
        ));
    }
    out
}

/// How far \[m\] `target` lies outside the box `[lo, hi]` (0 inside).
pub fn distance_from_box(lo: &Vec3, hi: &Vec3, target: &Vec3) -> f64 {
    let d = Vec3::from_fn(|i, _| (lo[i] - target[i]).max(target[i] - hi[i]).max(0.0));
    d.norm()
}

/// A message when the tool target lies more than [`TOOL_REACH_M`] from the organ's bounding box
/// `[lo, hi]` \[m\] (`None` within reach or for a non-finite target, which the tick refuses).
pub fn target_warning(lo: &Vec3, hi: &Vec3, target: &Vec3) -> Option<String> {
    let d = distance_from_box(lo, hi, target);
    (d.is_finite() && d > TOOL_REACH_M).then(|| {
        format!(
            "tool target ({}, {}, {}) m is {} m from the organ (its bounding box): positions are in metres (typed in mm?)",
            sig(target.x),
            sig(target.y),
            sig(target.z),
            sig(d)
        )
    })
}

/// The bounding box `(lo, hi)` of `points` \[m\] (an empty set gives an empty box at infinity).
pub fn bounding_box(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold((Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)), |(l, h), p| (l.inf(p), h.sup(p)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Damping, Elasticity};

    fn tissue(young: f64) -> Material {
        Material::new(Elasticity::YoungPoisson { young, poisson: 0.4 }, 1060.0, Damping::NONE).unwrap()
    }

    #[test]
    fn plausible_values_pass_and_unit_mistakes_are_named() {
        assert!(parameter_warnings(&tissue(30e3), 0.005).is_empty());
        assert!(parameter_warnings(&tissue(100.0), 0.05).is_empty());
        let w = parameter_warnings(&tissue(30.0), 0.005);
        assert_eq!(w.len(), 1);
        assert!(w[0].starts_with("Young's modulus 30 Pa") && w[0].contains("typed in kPa? 30 kPa is 30000 Pa"), "{}", w[0]);
        let w = parameter_warnings(&tissue(5e10), 5.0);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].contains("outside soft tissue") && !w[0].contains("typed in"), "{}", w[0]);
        assert!(w[1].contains("5 mm is 0.005 m"), "{}", w[1]);
    }

    #[test]
    fn a_target_a_metre_away_is_named() {
        let (lo, hi) = bounding_box(&[Vec3::zeros(), Vec3::repeat(0.1)]);
        assert_eq!(distance_from_box(&lo, &hi, &Vec3::new(0.05, 0.05, 0.05)), 0.0);
        assert!((distance_from_box(&lo, &hi, &Vec3::new(0.4, 0.05, 0.05)) - 0.3).abs() < 1e-12);
        assert!(target_warning(&lo, &hi, &Vec3::new(0.9, 0.05, 0.05)).is_none());
        assert!(target_warning(&lo, &hi, &Vec3::new(f64::NAN, 0.0, 0.0)).is_none());
        let w = target_warning(&lo, &hi, &Vec3::new(50.0, 20.0, 30.0)).unwrap();
        assert!(w.contains("m from the organ") && w.contains("mm?"), "{w}");
    }
}
