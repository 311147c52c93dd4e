//! Integrator objects: `SemiImplicit`, `BackwardEuler`, and their enums `Filter`, `Solver`
//! (`crates/palpate-core/src/integrate`). Defaults come from the core (`Integrator::*` constants),
//! so that Rust, Python, the CLI and the stubs cannot disagree.

use palpate_core::integrate::Filter;
use palpate_core::Integrator;
use pyo3::prelude::*;

use crate::conv;

/// The filter of the paper's semi-implicit scheme (eq. 34).
///
/// ``PAPER``: each node's block ``(I - dt^2/m J_F)^-1``, the paper's; stable only while the node
/// blocks dominate their coupling (not on every mesh at 1 ms). ``STABLE``: the blocks scaled by
/// ``alpha = lambda_max(blockdiag(K)^-1 K) / 2``, computed when the body is compiled: the
/// linearised scheme is stable at any dt (more numerical damping; large deformation can still
/// stiffen St. Venant-Kirchhoff past the rest bound).
#[pyclass(module = "palpate", name = "Filter", eq, eq_int, hash, frozen, from_py_object)]
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum PyFilter {
    #[pyo3(name = "PAPER")]
    Paper,
    #[pyo3(name = "STABLE")]
    Stable,
}

/// How backward Euler's implicit equation is solved.
///
/// ``QUASI_NEWTON`` (default): minimisation of the incremental potential by L-BFGS with the
/// factorised rest matrix as initial Hessian and a line search: stable at any press, one iteration
/// at small deformation. ``NEWTON``: the same minimisation by Newton's method (tangent solves by
/// conjugate gradients preconditioned by the rest factor): the accurate reference.
/// ``LINEARISED``: one solve with the rest matrix: fastest, but blows up under a firm press.
#[pyclass(module = "palpate", name = "Solver", eq, eq_int, hash, frozen, from_py_object)]
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum PySolver {
    #[pyo3(name = "QUASI_NEWTON")]
    QuasiNewton,
    #[pyo3(name = "NEWTON")]
    Newton,
    #[pyo3(name = "LINEARISED")]
    Linearised,
}

/// The paper's semi-implicit scheme (eq. 34): explicit elastic forces, each node's velocity
/// filtered by its own 3x3 block ``(I - alpha dt^2/m J_F)^-1`` precomputed at rest. Cheapest
/// per step; not momentum-conserving; over-damped on fine meshes.
///
/// ``SemiImplicit(filter=Filter.PAPER)``
#[pyclass(module = "palpate", name = "SemiImplicit", frozen)]
#[derive(Clone)]
pub struct PySemiImplicit {
    #[pyo3(get)]
    filter: PyFilter,
}

#[pymethods]
impl PySemiImplicit {
    #[new]
    #[pyo3(signature = (filter = PyFilter::Paper))]
    fn new(#[pyo3(from_py_with = conv::arg)] filter: PyFilter) -> Self {
        PySemiImplicit { filter }
    }
    fn __repr__(&self) -> String {
        match self.filter {
            PyFilter::Paper => "SemiImplicit()".into(),
            PyFilter::Stable => "SemiImplicit(filter=Filter.STABLE)".into(),
        }
    }
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PySemiImplicit>().map(|o| o.get().filter == self.filter).unwrap_or(false)
    }
}

/// Backward Euler.
///
/// ``BackwardEuler(solver=Solver.QUASI_NEWTON, *, max_iterations=None, tolerance=None, history=None)``
///
/// ``max_iterations`` caps the iterations of a step (a capped step still lowers the incremental
/// potential, so it stays stable); the iterations stop when the gradient of the incremental
/// potential falls under ``tolerance`` times the force scale (the applied forces and the momenta
/// over dt); ``history`` is the number of L-BFGS pairs (quasi-Newton only). ``None`` takes the
/// solver's default, the core's ``Integrator::QUASI_NEWTON_*`` / ``NEWTON_*`` constants
/// (``palpate.defaults.quasi_newton`` / ``palpate.defaults.newton``). The rest-linearised solver
/// takes none of them.
#[pyclass(module = "palpate", name = "BackwardEuler", frozen)]
#[derive(Clone)]
pub struct PyBackwardEuler {
    #[pyo3(get)]
    solver: PySolver,
    /// Iteration cap per step (None for the linearised solver).
    #[pyo3(get)]
    max_iterations: Option<usize>,
    /// Relative gradient tolerance (None for the linearised solver).
    #[pyo3(get)]
    tolerance: Option<f64>,
    /// L-BFGS pairs (quasi-Newton only, else None).
    #[pyo3(get)]
    history: Option<usize>,
}

impl PyBackwardEuler {
    fn integrator(&self) -> Integrator {
        match self.solver {
            PySolver::Linearised => Integrator::BackwardEulerLinear,
            PySolver::Newton => Integrator::BackwardEulerNewton {
                max_iterations: self.max_iterations.unwrap_or(Integrator::NEWTON_MAX_ITERATIONS),
                tolerance: self.tolerance.unwrap_or(Integrator::NEWTON_TOLERANCE),
            },
            PySolver::QuasiNewton => Integrator::BackwardEulerQuasiNewton {
                max_iterations: self.max_iterations.unwrap_or(Integrator::QUASI_NEWTON_MAX_ITERATIONS),
                tolerance: self.tolerance.unwrap_or(Integrator::QUASI_NEWTON_TOLERANCE),
                history: self.history.unwrap_or(Integrator::QUASI_NEWTON_HISTORY),
            },
        }
    }

    fn from_core(i: Integrator) -> Option<PyBackwardEuler> {
        Some(match i {
            Integrator::BackwardEulerLinear => PyBackwardEuler { solver: PySolver::Linearised, max_iterations: None, tolerance: None, history: None },
            Integrator::BackwardEulerNewton { max_iterations, tolerance } => {
                PyBackwardEuler { solver: PySolver::Newton, max_iterations: Some(max_iterations), tolerance: Some(tolerance), history: None }
            }
            Integrator::BackwardEulerQuasiNewton { max_iterations, tolerance, history } => {
                PyBackwardEuler { solver: PySolver::QuasiNewton, max_iterations: Some(max_iterations), tolerance: Some(tolerance), history: Some(history) }
            }
            Integrator::SemiImplicit { .. } => return None,
        })
    }
}

#[pymethods]
impl PyBackwardEuler {
    #[new]
    #[pyo3(signature = (solver = PySolver::QuasiNewton, *, max_iterations = None, tolerance = None, history = None))]
    fn new(
        #[pyo3(from_py_with = conv::arg)] solver: PySolver,
        max_iterations: Option<crate::errors::Int>,
        #[pyo3(from_py_with = conv::arg)] tolerance: Option<f64>,
        history: Option<crate::errors::Int>,
    ) -> PyResult<Self> {
        let (max_iterations, history) = (crate::errors::count_opt(max_iterations, "max_iterations")?, crate::errors::count_opt(history, "history")?);
        if solver == PySolver::Linearised && (max_iterations.is_some() || tolerance.is_some() || history.is_some()) {
            return Err(crate::errors::param_error_from("the LINEARISED solver takes no max_iterations, tolerance or history"));
        }
        if solver != PySolver::QuasiNewton && history.is_some() {
            return Err(crate::errors::param_error_from("history is an option of the QUASI_NEWTON solver only"));
        }
        let draft = PyBackwardEuler { solver, max_iterations, tolerance, history };
        let core = draft.integrator();
        core.check().map_err(crate::errors::param_error_from)?;
        Ok(PyBackwardEuler::from_core(core).expect("a backward Euler integrator"))
    }
    fn __repr__(&self) -> String {
        match self.solver {
            PySolver::Linearised => "BackwardEuler(Solver.LINEARISED)".into(),
            PySolver::Newton => {
                format!("BackwardEuler(Solver.NEWTON, max_iterations={}, tolerance={:e})", self.max_iterations.unwrap_or(0), self.tolerance.unwrap_or(0.0))
            }
            PySolver::QuasiNewton => format!(
                "BackwardEuler(Solver.QUASI_NEWTON, max_iterations={}, tolerance={:e}, history={})",
                self.max_iterations.unwrap_or(0),
                self.tolerance.unwrap_or(0.0),
                self.history.unwrap_or(0)
            ),
        }
    }
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PyBackwardEuler>().map(|o| o.get().integrator() == self.integrator()).unwrap_or(false)
    }
}

/// The core integrator an integrator object stands for (None: the default).
pub fn integrator_from_py(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Integrator> {
    let Some(obj) = obj else { return Ok(Integrator::default()) };
    if obj.is_none() {
        return Ok(Integrator::default());
    }
    if let Ok(si) = obj.cast::<PySemiImplicit>() {
        let filter = match si.get().filter {
            PyFilter::Paper => Filter::Paper,
            PyFilter::Stable => Filter::Stable,
        };
        return Ok(Integrator::SemiImplicit { filter });
    }
    if let Ok(be) = obj.cast::<PyBackwardEuler>() {
        return Ok(be.get().integrator());
    }
    let hint = if obj.cast::<pyo3::types::PyString>().is_ok() {
        " (integrators are objects, not strings)"
    } else {
        ""
    };
    Err(crate::errors::type_error(format!(
        "integrator must be palpate.SemiImplicit(...) or palpate.BackwardEuler(...), got {}{hint}",
        obj.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into())
    )))
}

/// A Python integrator object for a core integrator.
pub fn integrator_to_py(py: Python<'_>, i: Integrator) -> PyResult<Py<PyAny>> {
    Ok(match i {
        Integrator::SemiImplicit { filter } => {
            let filter = match filter {
                Filter::Paper => PyFilter::Paper,
                Filter::Stable => PyFilter::Stable,
            };
            Py::new(py, PySemiImplicit { filter })?.into_any()
        }
        other => Py::new(py, PyBackwardEuler::from_core(other).expect("a backward Euler integrator"))?.into_any(),
    })
}
