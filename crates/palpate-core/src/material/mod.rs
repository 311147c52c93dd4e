//! Isotropic hyperelastic material with Kelvin-Voigt-like viscous stress, paper §2.
//!
//! The elastic law is a [`Law`]: St. Venant-Kirchhoff (the paper's, the default) or the
//! compressible Neo-Hookean law of [`neo_hookean`] (same Lame constants, same small-strain
//! behaviour, but it resists strong compression and inversion, where SVK softens and collapses).
//!
//! * Elastic second Piola-Kirchhoff stress (paper eq. 9): `S = lambda tr(E) I + 2 mu E`, with the Green
//!   strain `E = 1/2 (F^T F - I)` (eq. 3-4, read as the paper's README prescribes: `F` is the
//!   deformation gradient, not the displacement gradient).
//! * Viscous stress (eq. 11): `S_v = phi tr(nu) I + 2 psi nu`. **Convention:** palpate defines the
//!   strain rate as the time derivative of the Green strain, `nu = dE/dt = 1/2 (F^T Fdot + Fdot^T F)`.
//!   The paper's eq. (10) (after O'Brien & Hodgins 1999) omits the 1/2, i.e. its strain rate is
//!   `2 dE/dt`; a paper value of (phi, psi) therefore corresponds to palpate's (2 phi, 2 psi).
//!   With this convention `phi` and `psi` are true viscosities \[Pa s\]: a small uniaxial strain
//!   rate `e_dot` costs stress `(phi + 2 psi) e_dot`, as `(lambda + 2 mu) e` for the elastic part.

pub(crate) mod linear;
pub mod neo_hookean;

pub use linear::{energy_density, green_strain, strain_rate, stress, viscous_stress};

use crate::error::MaterialError;

/// Elastic moduli, given either way. SI: pascals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Elasticity {
    /// Young's modulus `young` \[Pa\] and Poisson's ratio `poisson` \[-\], `-1 < poisson < 0.5`.
    YoungPoisson { young: f64, poisson: f64 },
    /// Lame's first parameter `lambda` \[Pa\] and shear modulus `mu` \[Pa\].
    Lame { lambda: f64, mu: f64 },
}

/// Viscous parameters of eq. (11), \[Pa s\], with palpate's strain-rate convention (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Damping {
    /// Volumetric viscosity `phi` \[Pa s\] (multiplies `tr(nu) I`).
    pub phi: f64,
    /// Shear viscosity `psi` \[Pa s\] (multiplies `2 nu`).
    pub psi: f64,
}

impl Damping {
    /// No viscous stress.
    pub const NONE: Damping = Damping { phi: 0.0, psi: 0.0 };
    /// Damping from the paper's (phi, psi) values, whose strain rate is twice palpate's.
    pub fn from_paper(phi: f64, psi: f64) -> Damping {
        Damping { phi: 2.0 * phi, psi: 2.0 * psi }
    }
}

/// The elastic (hyperelastic) law of a [`Material`]. Both use the material's Lame constants
/// `lambda`, `mu` and agree with linear elasticity at small strain; the viscous stress (eq. 11)
/// is the same for both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Law {
    /// St. Venant-Kirchhoff, the paper's law (eq. 9): `S = lambda tr(E) I + 2 mu E` on the Green
    /// strain. Cheap, but it softens under compression: its uniaxial nominal stress returns to
    /// zero as the stretch goes to 0, so a strong press can flatten or invert elements.
    #[default]
    StVenantKirchhoff,
    /// Compressible Neo-Hookean (Bonet & Wood; the `neo-Hookean` material of FEBio and SOFA):
    /// `psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2`, extended below `J_MIN` so that it is
    /// defined for inverted elements. See [`neo_hookean`].
    NeoHookean,
}

impl Law {
    /// A short human-readable name ("St. Venant-Kirchhoff", "Neo-Hookean").
    pub fn name(self) -> &'static str {
        match self {
            Law::StVenantKirchhoff => "St. Venant-Kirchhoff",
            Law::NeoHookean => "Neo-Hookean",
        }
    }
}

impl std::fmt::Display for Law {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A validated material. Construct with [`Material::new`] (St. Venant-Kirchhoff) and choose
/// another law with [`Material::with_law`]; fields are read through accessors so that an invalid
/// material cannot exist.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    lambda: f64,
    mu: f64,
    density: f64,
    damping: Damping,
    law: Law,
}

fn finite(name: &'static str, value: f64) -> Result<f64, MaterialError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(MaterialError::NonFinite { name, value })
    }
}

impl Material {
    /// A St. Venant-Kirchhoff material from its elastic moduli, density `density` \[kg/m^3\] and
    /// damping (see [`Material::with_law`] for another law).
    ///
    /// Errors: non-finite values; `young <= 0`; `poisson` outside (-1, 0.5); `mu <= 0`;
    /// `lambda + 2/3 mu <= 0` (non-positive bulk modulus); `density <= 0`; negative viscosities.
    pub fn new(elasticity: Elasticity, density: f64, damping: Damping) -> Result<Material, MaterialError> {
        let (lambda, mu) = match elasticity {
            Elasticity::YoungPoisson { young, poisson } => {
                let young = finite("Young's modulus E", young)?;
                let poisson = finite("Poisson ratio nu", poisson)?;
                if young <= 0.0 {
                    return Err(MaterialError::NotPositive { name: "Young's modulus E", value: young, unit: "Pa" });
                }
                if !(poisson > -1.0 && poisson < 0.5) {
                    return Err(MaterialError::Poisson(poisson));
                }
                let mu = young / (2.0 * (1.0 + poisson));
                let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
                (lambda, mu)
            }
            Elasticity::Lame { lambda, mu } => {
                let lambda = finite("Lame lambda", lambda)?;
                let mu = finite("shear modulus mu", mu)?;
                if mu <= 0.0 {
                    return Err(MaterialError::NotPositive { name: "shear modulus mu", value: mu, unit: "Pa" });
                }
                if lambda + 2.0 / 3.0 * mu <= 0.0 {
                    return Err(MaterialError::Bulk { lambda, mu });
                }
                (lambda, mu)
            }
        };
        let density = finite("density rho", density)?;
        if density <= 0.0 {
            return Err(MaterialError::NotPositive { name: "density rho", value: density, unit: "kg/m^3" });
        }
        let phi = finite("viscosity phi", damping.phi)?;
        let psi = finite("viscosity psi", damping.psi)?;
        if phi < 0.0 {
            return Err(MaterialError::Negative { name: "viscosity phi", value: phi, unit: "Pa s" });
        }
        if psi < 0.0 {
            return Err(MaterialError::Negative { name: "viscosity psi", value: psi, unit: "Pa s" });
        }
        Ok(Material { lambda, mu, density, damping: Damping { phi, psi }, law: Law::StVenantKirchhoff })
    }

    /// The same material (moduli, density, damping) with the elastic law `law`.
    ///
    /// Every valid (lambda, mu) is valid for both laws. The Neo-Hookean volumetric term is convex
    /// in `J` for `J < exp(1 + mu/lambda)` when `lambda >= 0` (Poisson's ratio >= 0, every soft
    /// tissue); see [`neo_hookean`].
    #[must_use]
    pub fn with_law(mut self, law: Law) -> Material {
        self.law = law;
        self
    }

    /// The same material with its Lame constants and viscosities times `factor` (density and law
    /// unchanged): a homogenised stiffness (`crate::hybrid::homogenise`). Errors: a factor that is
    /// not positive and finite.
    pub fn stiffened(self, factor: f64) -> Result<Material, MaterialError> {
        if !(factor > 0.0 && factor.is_finite()) {
            return Err(MaterialError::NotPositive { name: "stiffness factor", value: factor, unit: "-" });
        }
        Ok(Material {
            lambda: factor * self.lambda,
            mu: factor * self.mu,
            damping: Damping { phi: factor * self.damping.phi, psi: factor * self.damping.psi },
            ..self
        })
    }

    /// Myocardium-like soft tissue in SI: E = 30 kPa, nu = 0.4, rho = 1060 kg/m^3, no damping.
    /// palpate's default tissue: the hybrid builder's density, and the tissue of `palpate
    /// touch`, `palpate haptic`, the demo and scene files (Python: `palpate.defaults.tissue`),
    /// read from here so that they cannot disagree. (The shared benchmark protocol's tissue is
    /// 1000 kg/m^3: `palpate bench` keeps it, to compare with its peers.)
    pub fn myocardium() -> Material {
        Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1060.0, Damping::NONE).expect("preset is valid")
    }

    /// The paper's Table 1 "Ellipsoids Model" parameters in its (unstated, normalised) units:
    /// lambda = 5.5, mu = 2.5, phi = psi = 9e-5 (paper convention), density 1.
    pub fn paper_ellipsoids() -> Material {
        Material::new(Elasticity::Lame { lambda: 5.5, mu: 2.5 }, 1.0, Damping::from_paper(9.0e-5, 9.0e-5)).expect("preset is valid")
    }

    /// Lame's first parameter \[Pa\].
    pub fn lambda(&self) -> f64 {
        self.lambda
    }
    /// Shear modulus \[Pa\].
    pub fn mu(&self) -> f64 {
        self.mu
    }
    /// The elastic law.
    pub fn law(&self) -> Law {
        self.law
    }
    /// Mass density \[kg/m^3\].
    pub fn density(&self) -> f64 {
        self.density
    }
    /// Viscous parameters \[Pa s\].
    pub fn damping(&self) -> Damping {
        self.damping
    }
    /// Young's modulus \[Pa\].
    pub fn young(&self) -> f64 {
        self.mu * (3.0 * self.lambda + 2.0 * self.mu) / (self.lambda + self.mu)
    }
    /// Poisson's ratio \[-\].
    pub fn poisson(&self) -> f64 {
        self.lambda / (2.0 * (self.lambda + self.mu))
    }
    /// P-wave speed `sqrt((lambda + 2 mu) / rho)` \[m/s\]: sets explicit stability limits.
    pub fn wave_speed(&self) -> f64 {
        ((self.lambda + 2.0 * self.mu) / self.density).sqrt()
    }
    /// `true` when both viscosities are zero.
    pub fn is_undamped(&self) -> bool {
        self.damping.phi == 0.0 && self.damping.psi == 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn young_poisson_to_lame_matches_protocol() {
        let m = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap();
        assert!((m.mu() - 10714.285714285714).abs() < 1e-9);
        assert!((m.lambda() - 42857.142857142855).abs() < 1e-8);
        assert!((m.young() - 3.0e4).abs() < 1e-8);
        assert!((m.poisson() - 0.4).abs() < 1e-14);
    }

    #[test]
    fn law_defaults_to_svk_and_with_law_keeps_the_rest() {
        let m = Material::new(Elasticity::YoungPoisson { young: 3.0e4, poisson: 0.4 }, 1000.0, Damping { phi: 1.0, psi: 2.0 }).unwrap();
        assert_eq!(m.law(), Law::StVenantKirchhoff);
        assert_eq!(Material::myocardium().law(), Law::StVenantKirchhoff);
        let nh = m.with_law(Law::NeoHookean);
        assert_eq!(nh.law(), Law::NeoHookean);
        assert_eq!((nh.lambda(), nh.mu(), nh.density(), nh.damping()), (m.lambda(), m.mu(), m.density(), m.damping()));
        assert_ne!(nh, m, "materials with different laws must not compare equal");
        assert_eq!(nh.with_law(Law::StVenantKirchhoff), m);
    }

    #[test]
    fn nonsense_materials_are_refused() {
        let yp = |young, poisson| Elasticity::YoungPoisson { young, poisson };
        assert!(matches!(Material::new(yp(1e4, 0.5), 1e3, Damping::NONE), Err(MaterialError::Poisson(_))));
        assert!(matches!(Material::new(yp(1e4, 0.7), 1e3, Damping::NONE), Err(MaterialError::Poisson(_))));
        assert!(matches!(Material::new(yp(-1e4, 0.3), 1e3, Damping::NONE), Err(MaterialError::NotPositive { .. })));
        assert!(matches!(Material::new(yp(0.0, 0.3), 1e3, Damping::NONE), Err(MaterialError::NotPositive { .. })));
        assert!(matches!(Material::new(yp(f64::NAN, 0.3), 1e3, Damping::NONE), Err(MaterialError::NonFinite { .. })));
        assert!(matches!(Material::new(yp(1e4, 0.3), -1.0, Damping::NONE), Err(MaterialError::NotPositive { .. })));
        assert!(matches!(Material::new(yp(1e4, 0.3), f64::INFINITY, Damping::NONE), Err(MaterialError::NonFinite { .. })));
        let neg = Damping { phi: -1.0, psi: 0.0 };
        assert!(matches!(Material::new(yp(1e4, 0.3), 1e3, neg), Err(MaterialError::Negative { .. })));
        let lame = |lambda, mu| Elasticity::Lame { lambda, mu };
        assert!(matches!(Material::new(lame(1.0, -1.0), 1e3, Damping::NONE), Err(MaterialError::NotPositive { .. })));
        assert!(matches!(Material::new(lame(-10.0, 1.0), 1e3, Damping::NONE), Err(MaterialError::Bulk { .. })));
    }
}
