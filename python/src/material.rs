//! `palpate.Law` and `palpate.Material` (`crates/palpate-core/src/material`).

use palpate_core::material::{Damping, Elasticity, Law, Material};
use pyo3::prelude::*;

use crate::conv;
use crate::errors::{self, MaterialError};

/// The elastic law of a ``Material`` (``palpate_core::material::Law``); both use the material's
/// Lame constants and agree with linear elasticity at small strain.
///
/// * ``ST_VENANT_KIRCHHOFF`` (default, the paper's eq. 9): ``S = lambda tr(E) I + 2 mu E`` on the
///   Green strain. It softens under strong compression (its uniaxial stress returns to 0 as the
///   stretch goes to 0), so a hard press can flatten or invert elements.
/// * ``NEO_HOOKEAN``: compressible Neo-Hookean (Bonet & Wood; FEBio's ``neo-Hookean``),
///   ``psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2``, continued below ``J = 0.1`` by its
///   second-order Taylor polynomial in ``J`` (finite for inverted elements). It resists
///   compression. FEM bodies only: ``ParticleBody`` refuses it (``MaterialError``).
#[pyclass(module = "palpate", name = "Law", eq, eq_int, hash, frozen, from_py_object)]
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub enum PyLaw {
    #[pyo3(name = "ST_VENANT_KIRCHHOFF")]
    StVenantKirchhoff,
    #[pyo3(name = "NEO_HOOKEAN")]
    NeoHookean,
}

impl From<PyLaw> for Law {
    fn from(l: PyLaw) -> Law {
        match l {
            PyLaw::StVenantKirchhoff => Law::StVenantKirchhoff,
            PyLaw::NeoHookean => Law::NeoHookean,
        }
    }
}

impl From<Law> for PyLaw {
    fn from(l: Law) -> PyLaw {
        match l {
            Law::StVenantKirchhoff => PyLaw::StVenantKirchhoff,
            Law::NeoHookean => PyLaw::NeoHookean,
        }
    }
}

impl PyLaw {
    fn py_name(self) -> &'static str {
        match self {
            PyLaw::StVenantKirchhoff => "Law.ST_VENANT_KIRCHHOFF",
            PyLaw::NeoHookean => "Law.NEO_HOOKEAN",
        }
    }
}

/// An isotropic hyperelastic material with viscous damping (paper eq. 9, 11).
///
/// ``Material(young=None, poisson=None, lame_lambda=None, lame_mu=None, density=1000.0, phi=0.0,
/// psi=0.0, law=Law.ST_VENANT_KIRCHHOFF)``
///
/// Give exactly one pair: ``young`` [Pa] and ``poisson`` [-] (in (-1, 0.5)), or ``lame_lambda``
/// [Pa] and ``lame_mu`` [Pa] (shear modulus). ``density`` [kg/m^3]. ``phi`` and ``psi`` [Pa s] are
/// the volumetric and shear viscosities of the viscous stress ``phi tr(nu) I + 2 psi nu`` with the
/// strain rate ``nu = dE/dt`` (palpate's convention; the paper's values correspond to twice
/// theirs, see ``palpate_core::material``). ``law``: the elastic law (``Law``), St. Venant-Kirchhoff
/// (the paper's) by default, or ``Law.NEO_HOOKEAN``.
///
/// Raises ``MaterialError`` for unphysical values or a missing / doubled pair.
#[pyclass(module = "palpate", name = "Material", frozen)]
#[derive(Clone)]
pub struct PyMaterial {
    pub inner: Material,
}

#[pymethods]
impl PyMaterial {
    #[new]
    #[pyo3(signature = (young = None, poisson = None, lame_lambda = None, lame_mu = None, density = 1000.0, phi = 0.0, psi = 0.0, law = PyLaw::StVenantKirchhoff))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        #[pyo3(from_py_with = conv::arg)] young: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] poisson: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] lame_lambda: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] lame_mu: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] density: f64,
        #[pyo3(from_py_with = conv::arg)] phi: f64,
        #[pyo3(from_py_with = conv::arg)] psi: f64,
        #[pyo3(from_py_with = conv::arg)] law: PyLaw,
    ) -> PyResult<Self> {
        let elasticity = match (young, poisson, lame_lambda, lame_mu) {
            (Some(young), Some(poisson), None, None) => Elasticity::YoungPoisson { young, poisson },
            (None, None, Some(lambda), Some(mu)) => Elasticity::Lame { lambda, mu },
            (None, None, None, None) => return Err(MaterialError::new_err("give the elastic moduli: young and poisson, or lame_lambda and lame_mu")),
            (y, p, l, m) if (y.is_some() || p.is_some()) && (l.is_some() || m.is_some()) => {
                return Err(MaterialError::new_err("give either (young, poisson) or (lame_lambda, lame_mu), not both"))
            }
            (y, _, None, None) => {
                let missing = if y.is_none() { "young" } else { "poisson" };
                return Err(MaterialError::new_err(format!("young and poisson go together: {missing} is missing")));
            }
            (_, _, l, _) => {
                let missing = if l.is_none() { "lame_lambda" } else { "lame_mu" };
                return Err(MaterialError::new_err(format!("lame_lambda and lame_mu go together: {missing} is missing")));
            }
        };
        let inner = Material::new(elasticity, density, Damping { phi, psi }).map_err(errors::material_error)?.with_law(law.into());
        Ok(PyMaterial { inner })
    }

    /// Myocardium-like soft tissue in SI: E = 30 kPa, nu = 0.4, density 1060 kg/m^3, no damping.
    #[staticmethod]
    fn myocardium() -> Self {
        PyMaterial { inner: Material::myocardium() }
    }

    /// The paper's Table 1 "Ellipsoids Model" values in its normalised (unit-less) units:
    /// lambda = 5.5, mu = 2.5, density 1, phi = psi = 9e-5 (paper convention, stored doubled).
    #[staticmethod]
    fn paper_ellipsoids() -> Self {
        PyMaterial { inner: Material::paper_ellipsoids() }
    }

    /// The elastic law (``Law``).
    #[getter]
    fn law(&self) -> PyLaw {
        self.inner.law().into()
    }
    /// Young's modulus E [Pa].
    #[getter]
    fn young(&self) -> f64 {
        self.inner.young()
    }
    /// Poisson's ratio nu [-].
    #[getter]
    fn poisson(&self) -> f64 {
        self.inner.poisson()
    }
    /// Lame's first parameter lambda [Pa].
    #[getter]
    fn lame_lambda(&self) -> f64 {
        self.inner.lambda()
    }
    /// Shear modulus mu [Pa].
    #[getter]
    fn lame_mu(&self) -> f64 {
        self.inner.mu()
    }
    /// Mass density [kg/m^3].
    #[getter]
    fn density(&self) -> f64 {
        self.inner.density()
    }
    /// Volumetric viscosity phi [Pa s].
    #[getter]
    fn phi(&self) -> f64 {
        self.inner.damping().phi
    }
    /// Shear viscosity psi [Pa s].
    #[getter]
    fn psi(&self) -> f64 {
        self.inner.damping().psi
    }
    /// P-wave speed sqrt((lambda + 2 mu) / density) [m/s].
    #[getter]
    fn wave_speed(&self) -> f64 {
        self.inner.wave_speed()
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        format!(
            "Material(young={}, poisson={}, density={}, phi={}, psi={}, law={})",
            crate::body::sig4(m.young()),
            crate::body::sig4(m.poisson()),
            crate::body::sig4(m.density()),
            crate::body::sig4(m.damping().phi),
            crate::body::sig4(m.damping().psi),
            PyLaw::from(m.law()).py_name()
        )
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PyMaterial>().map(|o| o.get().inner == self.inner).unwrap_or(false)
    }
}
