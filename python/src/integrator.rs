//! Integrator objects: `SemiImplicit`, `BackwardEuler` (`crates/palpate-core/src/integrate`).

use palpate_core::Integrator;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// The paper's semi-implicit scheme (eq. 34): explicit elastic forces, each node's velocity
/// filtered by its own 3x3 block ``(I - dt^2/m J_F)^-1`` precomputed at rest. Cheapest per step.
#[pyclass(module = "palpate", name = "SemiImplicit", frozen)]
#[derive(Clone)]
pub struct PySemiImplicit;

#[pymethods]
impl PySemiImplicit {
    #[new]
    fn new() -> Self {
        PySemiImplicit
    }
    fn __repr__(&self) -> &'static str {
        "SemiImplicit()"
    }
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PySemiImplicit>().is_ok()
    }
}

/// Backward Euler.
///
/// ``BackwardEuler(newton=False)``: linearised at rest; the system ``M - dt D0 - dt^2 K0`` is
/// factorised once per time step size and each step is one sparse solve.
///
/// ``BackwardEuler(newton=True, max_iterations=20, tolerance=1e-9)``: Newton's method with the
/// current tangent, refactorised each iteration, until the residual has dropped by
/// ``tolerance`` (relative) or after ``max_iterations`` (the step is then accepted and reported
/// unconverged).
#[pyclass(module = "palpate", name = "BackwardEuler", frozen)]
#[derive(Clone)]
pub struct PyBackwardEuler {
    #[pyo3(get)]
    newton: bool,
    #[pyo3(get)]
    max_iterations: usize,
    #[pyo3(get)]
    tolerance: f64,
}

#[pymethods]
impl PyBackwardEuler {
    #[new]
    #[pyo3(signature = (newton = false, max_iterations = 20, tolerance = 1e-9))]
    fn new(newton: bool, max_iterations: usize, tolerance: f64) -> PyResult<Self> {
        if max_iterations == 0 {
            return Err(PyValueError::new_err("max_iterations must be at least 1"));
        }
        if !(tolerance > 0.0 && tolerance < 1.0) {
            return Err(PyValueError::new_err(format!("tolerance = {tolerance} must lie in (0, 1) (a relative residual reduction)")));
        }
        Ok(PyBackwardEuler { newton, max_iterations, tolerance })
    }
    fn __repr__(&self) -> String {
        if self.newton {
            format!("BackwardEuler(newton=True, max_iterations={}, tolerance={:e})", self.max_iterations, self.tolerance)
        } else {
            "BackwardEuler(newton=False)".into()
        }
    }
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PyBackwardEuler>().map(|o| {
            let o = o.get();
            o.newton == self.newton && (!self.newton || (o.max_iterations == self.max_iterations && o.tolerance == self.tolerance))
        }).unwrap_or(false)
    }
}

/// The core integrator an integrator object stands for.
pub fn integrator_from_py(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Integrator> {
    let Some(obj) = obj else { return Ok(Integrator::BackwardEulerLinear) };
    if obj.is_none() {
        return Ok(Integrator::BackwardEulerLinear);
    }
    if obj.cast::<PySemiImplicit>().is_ok() {
        return Ok(Integrator::SemiImplicit);
    }
    if let Ok(be) = obj.cast::<PyBackwardEuler>() {
        let be = be.get();
        return Ok(if be.newton {
            Integrator::BackwardEulerNewton { max_iterations: be.max_iterations, tolerance: be.tolerance }
        } else {
            Integrator::BackwardEulerLinear
        });
    }
    let hint = if obj.cast::<pyo3::types::PyString>().is_ok() { " (integrators are objects, not strings)" } else { "" };
    Err(PyTypeError::new_err(format!(
        "integrator must be palpate.SemiImplicit() or palpate.BackwardEuler(...), got {}{hint}",
        obj.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into())
    )))
}

/// A Python integrator object for a core integrator.
pub fn integrator_to_py(py: Python<'_>, i: Integrator) -> PyResult<Py<PyAny>> {
    Ok(match i {
        Integrator::SemiImplicit => Py::new(py, PySemiImplicit)?.into_any(),
        Integrator::BackwardEulerLinear => {
            Py::new(py, PyBackwardEuler { newton: false, max_iterations: 20, tolerance: 1e-9 })?.into_any()
        }
        Integrator::BackwardEulerNewton { max_iterations, tolerance } => {
            Py::new(py, PyBackwardEuler { newton: true, max_iterations, tolerance })?.into_any()
        }
    })
}
