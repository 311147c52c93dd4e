//! The meshfree side: `palpate.Kernel`, `palpate.ParticleBody` (`palpate_core::meshfree`),
//! `palpate.TriSurface`, `ellipsoid_surface`, `sample_inside`, `sample_between`
//! (`palpate_core::mesh::{surface, sample}`); its errors are `palpate.SurfaceError` (errors.rs).
//! Building, stepping, sampling and the timed run release the GIL.

use std::collections::HashSet;
use std::ffi::CString;
use std::time::Instant;

use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use palpate_core::error::ModelError as CoreModelError;
use palpate_core::mesh::{self, TriSurface};
use palpate_core::meshfree::{Kernel, ParticleModel, ParticleModelBuilder, ParticleState, ParticleWorkspace, DEFAULT_HOURGLASS};
use palpate_core::Vec3;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::IntoPyObjectExt;
use pyo3::types::PyDict;

use crate::conv;
use crate::errors::{self, surface_error, MeshWarning};
use crate::material::PyMaterial;

/// Register the meshfree classes and functions.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyKernel>()?;
    m.add_class::<PyParticleBody>()?;
    m.add_class::<PyTriSurface>()?;
    m.add_function(wrap_pyfunction!(ellipsoid_surface, m)?)?;
    m.add_function(wrap_pyfunction!(sample_inside, m)?)?;
    m.add_function(wrap_pyfunction!(sample_between, m)?)?;
    m.add_function(wrap_pyfunction!(simd_path, m)?)?;
    m.add_function(wrap_pyfunction!(set_simd_enabled, m)?)?;
    Ok(())
}

/// The copy of the particle hot loop that runs on this CPU: ``"avx2+fma"`` or ``"baseline"``.
#[pyfunction]
fn simd_path() -> &'static str {
    palpate_core::meshfree::simd_path()
}

/// Allow (default) or forbid the AVX2 + FMA copy of the particle hot loop, process-wide (for
/// comparing the two copies; results agree to round-off).
#[pyfunction]
fn set_simd_enabled(enabled: bool) {
    palpate_core::meshfree::set_simd_enabled(enabled)
}


// ---------------------------------------------------------------------------------------------
// Array helpers local to the particle API
// ---------------------------------------------------------------------------------------------

fn asarray<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let np = obj.py().import("numpy")?;
    np.call_method1("asarray", (obj,))
        .ok()
        .and_then(|a| a.cast_into::<PyUntypedArray>().ok())
        .ok_or_else(|| PyTypeError::new_err(format!("{what} must be an array-like of numbers")))
}

fn shape_str(s: &[usize]) -> String {
    match s.len() {
        1 => format!("({},)", s[0]),
        _ => format!("({})", s.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// `obj` converted to a C-contiguous array of `dtype` (after a dtype-kind check).
fn converted<'py>(a: &Bound<'py, PyUntypedArray>, what: &str, kinds: &[u8], dtype: &str, hint: &str) -> PyResult<Bound<'py, PyAny>> {
    let kind = a.dtype().kind();
    if !kinds.contains(&kind) {
        let d = a.dtype().str().map(|s| s.to_string()).unwrap_or_default();
        return Err(PyTypeError::new_err(format!("{what} must be {hint}, got dtype {d}")));
    }
    let np = a.py().import("numpy")?;
    np.call_method1("ascontiguousarray", (a, dtype))
}

/// Real values of a 1-D array of length `n`, as f64.
fn reals_1d(obj: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<f64>> {
    let a = asarray(obj, what)?;
    if a.shape() != [n] {
        return Err(PyValueError::new_err(format!("{what} must have shape ({n},) (one per particle), got {}", shape_str(a.shape()))));
    }
    let c = converted(&a, what, b"fiu", "float64", "real numbers")?;
    let arr = c.cast::<PyArray1<f64>>()?.readonly();
    Ok(arr.as_slice()?.to_vec())
}

/// Triangles `(m, 3)` as signed indices (any integer dtype).
pub fn triangles_arg(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<[i64; 3]>> {
    let a = asarray(obj, what)?;
    let s = a.shape();
    if !(s.len() == 2 && s[1] == 3) && !(s.len() == 1 && s[0] == 0) {
        return Err(PyValueError::new_err(format!("{what} must have shape (m, 3), got {}", shape_str(s))));
    }
    if s.len() == 1 {
        return Ok(Vec::new());
    }
    let c = converted(&a, what, b"iu", "int64", "an integer array (convert with .astype(np.int64) if the values are whole)")?;
    let arr = c.cast::<PyArray2<i64>>()?.readonly();
    Ok(arr.as_slice()?.chunks_exact(3).map(|r| [r[0], r[1], r[2]]).collect())
}

/// Particle indices: a 1-D integer array-like in `0..n`, or a boolean mask of length `n`; with
/// `unique`, a repeated index is an error.
fn particle_indices(obj: &Bound<'_, PyAny>, what: &str, n: usize, unique: bool) -> PyResult<Vec<usize>> {
    let a = asarray(obj, what)?;
    let s = a.shape().to_vec();
    if s.len() != 1 {
        return Err(PyValueError::new_err(format!(
            "{what} must be a 1-D array of particle indices (or a boolean mask of length {n}), got shape {}",
            shape_str(&s)
        )));
    }
    if s[0] == 0 {
        return Ok(Vec::new());
    }
    let idx: Vec<usize> = if a.dtype().kind() == b'b' {
        if s[0] != n {
            return Err(PyValueError::new_err(format!("{what}: a boolean mask must have length {n} (one per particle), got {}", s[0])));
        }
        let c = converted(&a, what, b"b", "bool", "booleans")?;
        let m = c.cast::<PyArray1<bool>>()?.readonly();
        m.as_slice()?.iter().enumerate().filter(|(_, &b)| b).map(|(i, _)| i).collect()
    } else {
        let c = converted(&a, what, b"iu", "int64", "an integer array of particle indices or a boolean mask")?;
        let v = c.cast::<PyArray1<i64>>()?.readonly();
        let mut out = Vec::with_capacity(s[0]);
        for &i in v.as_slice()? {
            if i < 0 || i as u64 >= n as u64 {
                return Err(PyValueError::new_err(format!("{what}: particle index {i} out of range (the body has {n} particles)")));
            }
            out.push(i as usize);
        }
        out
    };
    if unique {
        let mut seen = HashSet::with_capacity(idx.len());
        if let Some(&i) = idx.iter().find(|&&i| !seen.insert(i)) {
            return Err(PyValueError::new_err(format!("{what}: particle {i} is listed more than once")));
        }
    }
    Ok(idx)
}

pub fn warn(py: Python<'_>, msg: String) -> PyResult<()> {
    let msg = CString::new(msg).unwrap_or_else(|_| CString::new("surface warning").unwrap());
    PyErr::warn(py, &py.get_type::<MeshWarning>(), &msg, 1)
}

// ---------------------------------------------------------------------------------------------
// Kernel
// ---------------------------------------------------------------------------------------------

/// The smoothing kernel of a particle body (``palpate_core::meshfree::kernel``); every kernel
/// vanishes at the support radius ``h``.
///
/// * ``WENDLAND_C2`` (default): ``21/(2 pi h^3) (1-q)^4 (1+4q)``, ``q = r/h``.
/// * ``CUBIC_SPLINE``: the M4 spline with smoothing length ``h/2``.
/// * ``LINEAR_LENNARD_JONES``: the paper's linearised Lennard-Jones tent, ``3/(pi h^3) (1-q)``.
#[pyclass(module = "palpate", name = "Kernel", eq, eq_int, hash, frozen, from_py_object)]
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub enum PyKernel {
    #[pyo3(name = "WENDLAND_C2")]
    WendlandC2,
    #[pyo3(name = "CUBIC_SPLINE")]
    CubicSpline,
    #[pyo3(name = "LINEAR_LENNARD_JONES")]
    LinearLennardJones,
}

impl From<PyKernel> for Kernel {
    fn from(k: PyKernel) -> Kernel {
        match k {
            PyKernel::WendlandC2 => Kernel::WendlandC2,
            PyKernel::CubicSpline => Kernel::CubicSpline,
            PyKernel::LinearLennardJones => Kernel::LinearLennardJones,
        }
    }
}

impl From<Kernel> for PyKernel {
    fn from(k: Kernel) -> PyKernel {
        match k {
            Kernel::WendlandC2 => PyKernel::WendlandC2,
            Kernel::CubicSpline => PyKernel::CubicSpline,
            Kernel::LinearLennardJones => PyKernel::LinearLennardJones,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// ParticleBody
// ---------------------------------------------------------------------------------------------

/// A meshfree (particle) solid: the continuum law of ``Material`` on particles (paper §3.2),
/// stepped by explicit Verlet sub-steps (eq. 33) at the stable step.
///
/// ``ParticleBody(positions, masses, material, support_radius, kernel=Kernel.WENDLAND_C2,
/// fixed=None, gravity=None, hourglass=0.5)``
///
/// Parameters
/// ----------
/// positions : array_like, shape (n, 3)
///     Rest positions [m].
/// masses : array_like, shape (n,)
///     Masses [kg], positive.
/// material : Material
/// support_radius : float
///     Kernel support radius h [m] (neighbours within h at rest; typically 1.5-2 spacings).
/// kernel : Kernel
/// fixed : array_like of int, or bool mask of shape (n,), optional
///     Particles held at their rest position.
/// gravity : (3,) float, optional
///     [m/s^2], default zero.
/// hourglass : float
///     Dimensionless hourglass-control stiffness kappa (0 disables it).
///
/// Raises ``ModelError`` naming the particle (non-finite position, non-positive mass, too few
/// neighbours to span 3D) or the parameter; ``ValueError`` / ``TypeError`` for shapes and dtypes.
///
/// All particles start active; ``active`` selects the simulated ones (the others are frozen but
/// still shape their active neighbours' deformation). Getters return copies.
#[pyclass(module = "palpate", name = "ParticleBody")]
pub struct PyParticleBody {
    model: ParticleModel,
    state: ParticleState,
    ws: ParticleWorkspace,
    material: Py<PyMaterial>,
}

/// What `run_timed` measured.
struct TimedRun {
    tick_wall: Vec<f64>,
    substeps: usize,
    substep_dt: f64,
    error: Option<String>,
}

#[pymethods]
impl PyParticleBody {
    #[new]
    #[pyo3(signature = (positions, masses, material, support_radius, kernel = PyKernel::WendlandC2, fixed = None, gravity = None, hourglass = DEFAULT_HOURGLASS, min_relative_weight = palpate_core::meshfree::DEFAULT_MIN_WEIGHT))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        masses: &Bound<'_, PyAny>,
        material: Bound<'_, PyMaterial>,
        support_radius: f64,
        kernel: PyKernel,
        fixed: Option<&Bound<'_, PyAny>>,
        gravity: Option<&Bound<'_, PyAny>>,
        hourglass: f64,
        min_relative_weight: f64,
    ) -> PyResult<Self> {
        let p = conv::points(positions, "positions")?;
        let n = p.len();
        let m = reals_1d(masses, "masses", n)?;
        let fixed = match fixed {
            Some(f) if !f.is_none() => particle_indices(f, "fixed", n, false)?,
            _ => Vec::new(),
        };
        let gravity = match gravity {
            Some(g) if !g.is_none() => conv::vec3(g, "gravity")?,
            _ => Vec3::zeros(),
        };
        let builder = ParticleModelBuilder::new(p.iter().map(|q| Vec3::new(q[0], q[1], q[2])).collect(), m, material.get().inner, support_radius)
            .kernel(kernel.into())
            .fixed_particles(fixed)
            .gravity(gravity)
            .hourglass(hourglass)
            .min_relative_weight(min_relative_weight);
        let model = py.detach(|| builder.build()).map_err(|e: CoreModelError| errors::model_error(e))?;
        let state = ParticleState::rest(&model);
        let ws = ParticleWorkspace::new(&model);
        Ok(PyParticleBody { model, state, ws, material: material.unbind() })
    }

    /// Advance ``n`` steps of ``dt`` [s] with the current external forces (GIL released). Each
    /// step takes ``substeps(dt)`` explicit sub-steps.
    ///
    /// Returns a dict: ``steps``, ``substeps`` (per step), ``substep_dt`` [s].
    /// Raises ``StepError`` if a step fails; the steps before it are kept and the body is left as
    /// it was before the failing step.
    #[pyo3(signature = (n = 1, dt = 1e-3))]
    fn step<'py>(mut slf: PyRefMut<'py, Self>, py: Python<'py>, n: usize, dt: f64) -> PyResult<Bound<'py, PyDict>> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(errors::step_error(palpate_core::StepError::BadTimeStep(dt), ""));
        }
        let this = &mut *slf;
        let (model, state, ws) = (&this.model, &mut this.state, &mut this.ws);
        py.detach(|| (0..n).try_for_each(|k| model.step(state, ws, dt).map(|_| ()).map_err(|e| (k, e))))
            .map_err(|(k, e)| errors::step_error(e, &format!("in step {} of {n}", k + 1)))?;
        let substeps = this.model.substeps(dt);
        let d = PyDict::new(py);
        d.set_item("steps", n)?;
        d.set_item("substep_dt", dt / substeps as f64)?;
        d.set_item("substeps", substeps)?;
        Ok(d)
    }

    /// ``ticks`` steps of ``dt`` [s] with the current external forces, each step timed in Rust
    /// (``std::time::Instant``, GIL released) for benchmarks.
    ///
    /// Returns a dict: ``ticks`` (completed), ``tick_wall_s`` (float64 (ticks,): wall time of each
    /// step [s]), ``substeps`` (per step), ``substep_dt`` [s], ``error`` (why the run stopped
    /// early, else None). Stops early when a step fails or the summed wall time exceeds
    /// ``max_wall_s`` [s].
    #[pyo3(signature = (ticks, dt = 1e-3, max_wall_s = None))]
    fn run_timed<'py>(mut slf: PyRefMut<'py, Self>, py: Python<'py>, ticks: usize, dt: f64, max_wall_s: Option<f64>) -> PyResult<Bound<'py, PyDict>> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(PyValueError::new_err(format!("dt = {dt} s must be positive and finite")));
        }
        let this = &mut *slf;
        let (model, state, ws) = (&this.model, &mut this.state, &mut this.ws);
        let substeps = model.substeps(dt);
        let run = py.detach(|| {
            let mut out = TimedRun { tick_wall: Vec::with_capacity(ticks), substeps, substep_dt: dt / substeps as f64, error: None };
            let mut total = 0.0;
            for k in 0..ticks {
                let t0 = Instant::now();
                let r = model.step(state, ws, dt);
                let w = t0.elapsed().as_secs_f64();
                match r {
                    Ok(rep) => {
                        out.tick_wall.push(w);
                        (out.substeps, out.substep_dt) = (rep.substeps, rep.substep_dt);
                    }
                    Err(e) => {
                        out.error = Some(format!("tick {} of {ticks}: {e}", k + 1));
                        break;
                    }
                }
                total += w;
                if let Some(cap) = max_wall_s {
                    if total > cap && k + 1 < ticks {
                        out.error = Some(format!("stopped after {} of {ticks} ticks: wall-clock cap of {cap} s reached", k + 1));
                        break;
                    }
                }
            }
            out
        });
        let d = PyDict::new(py);
        d.set_item("ticks", run.tick_wall.len())?;
        d.set_item("tick_wall_s", conv::f64s_to_py(py, &run.tick_wall))?;
        d.set_item("substeps", run.substeps)?;
        d.set_item("substep_dt", run.substep_dt)?;
        d.set_item("error", run.error)?;
        Ok(d)
    }

    /// Set the external force on every particle [N], (n, 3); held until changed.
    fn set_forces(&mut self, forces: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.f_ext = conv::vec3s(forces, "forces", self.model.n_particles(), true)?;
        Ok(())
    }

    /// Set the positions of every particle [m], (n, 3) (e.g. an initial deformation).
    fn set_positions(&mut self, positions: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.x = conv::vec3s(positions, "positions", self.model.n_particles(), true)?;
        Ok(())
    }

    /// Set the velocities of every particle [m/s], (n, 3).
    fn set_velocities(&mut self, velocities: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.v = conv::vec3s(velocities, "velocities", self.model.n_particles(), true)?;
        Ok(())
    }

    /// External forces [N], (n, 3) (a copy).
    #[getter]
    fn forces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.f_ext)
    }

    /// Positions [m], (n, 3) (a copy).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.x)
    }

    /// Velocities [m/s], (n, 3) (a copy; half-step velocities of the Verlet scheme).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.v)
    }

    /// Displacements from the rest positions [m], (n, 3).
    #[getter]
    fn displacements<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let u: Vec<Vec3> = self.state.x.iter().zip(self.model.rest_positions()).map(|(x, x0)| x - x0).collect();
        conv::vec3s_to_py(py, &u)
    }

    /// Rest positions [m], (n, 3).
    #[getter]
    fn rest_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, self.model.rest_positions())
    }

    /// Indices of the active (simulated) particles, int64 (k,). Set with an index array or a
    /// boolean mask (each particle at most once); the other particles are frozen where they are.
    #[getter]
    fn get_active<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::usizes_to_py(py, &self.state.active)
    }

    #[setter]
    fn set_active(&mut self, active: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.active = particle_indices(active, "active", self.model.n_particles(), true)?;
        Ok(())
    }

    /// Indices of the fixed particles, int64 (k,), ascending.
    #[getter]
    fn fixed<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let idx: Vec<usize> = self.model.fixed().iter().enumerate().filter(|(_, &f)| f).map(|(i, _)| i).collect();
        conv::usizes_to_py(py, &idx)
    }

    /// Largest stable explicit sub-step [s] (with the core's safety factor).
    #[getter]
    fn stable_dt(&self) -> f64 {
        self.model.stable_dt()
    }

    /// Largest angular eigenfrequency of the rest-linearised body [rad/s].
    #[getter]
    fn omega_max(&self) -> f64 {
        self.model.omega_max()
    }

    /// Sub-steps one step of ``dt`` [s] takes.
    fn substeps(&self, dt: f64) -> PyResult<usize> {
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(PyValueError::new_err(format!("dt = {dt} s must be positive and finite")));
        }
        Ok(self.model.substeps(dt))
    }

    /// Number of particles n.
    #[getter]
    fn n_particles(&self) -> usize {
        self.model.n_particles()
    }

    /// Number of directed neighbour pairs (the sum of the neighbour counts).
    #[getter]
    fn n_pairs(&self) -> usize {
        self.model.n_pairs()
    }

    /// Neighbours of particle ``i`` at rest, int64, ascending.
    fn neighbours<'py>(&self, py: Python<'py>, i: usize) -> PyResult<Bound<'py, PyArray1<i64>>> {
        if i >= self.model.n_particles() {
            return Err(PyValueError::new_err(format!("particle index {i} out of range (the body has {} particles)", self.model.n_particles())));
        }
        Ok(conv::usizes_to_py(py, self.model.neighbours(i)))
    }

    /// Kernel-sum densities [kg/m^3], (n,) (Shepard-normalised, eq. 25).
    #[getter]
    fn densities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::f64s_to_py(py, self.model.densities())
    }

    /// Particle volumes m / rho [m^3], (n,).
    #[getter]
    fn volumes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::f64s_to_py(py, self.model.volumes())
    }

    /// Masses [kg], (n,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::f64s_to_py(py, self.model.masses())
    }

    /// The kernel.
    #[getter]
    fn kernel(&self) -> PyKernel {
        self.model.kernel().into()
    }

    /// Support radius [m].
    #[getter]
    fn support_radius(&self) -> f64 {
        self.model.support()
    }

    /// Hourglass-control stiffness kappa [-].
    #[getter]
    fn hourglass(&self) -> f64 {
        self.model.hourglass()
    }

    /// The material.
    #[getter]
    fn material(&self, py: Python<'_>) -> Py<PyMaterial> {
        self.material.clone_ref(py)
    }

    /// Simulated time [s].
    #[getter]
    fn time(&self) -> f64 {
        self.state.t
    }

    /// Elastic energy of the current positions [J] (including the hourglass-control energy).
    fn strain_energy(&self) -> f64 {
        self.model.strain_energy(&self.state.x)
    }

    /// Kinetic energy [J].
    fn kinetic_energy(&self) -> f64 {
        self.model.kinetic_energy(&self.state.v)
    }

    /// Linear momentum [kg m/s], (3,).
    fn momentum<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let p = self.model.momentum(&self.state.v);
        conv::f64s_to_py(py, &[p.x, p.y, p.z])
    }

    /// Internal (elastic + viscous + hourglass) forces at the current state [N], (n, 3).
    fn internal_forces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let mut f = vec![Vec3::zeros(); self.model.n_particles()];
        self.model.internal_forces(&self.state.x, Some(&self.state.v), &mut f);
        conv::vec3s_to_py(py, &f)
    }

    /// Back to rest: rest positions, zero velocity, time 0, no external force. The active set is kept.
    fn reset(&mut self) {
        let active = std::mem::take(&mut self.state.active);
        self.state = ParticleState::rest(&self.model);
        self.state.active = active;
    }

    fn __len__(&self) -> usize {
        self.model.n_particles()
    }

    fn __repr__(&self) -> String {
        format!(
            "ParticleBody(n_particles={}, n_pairs={}, active={}, fixed={}, kernel={:?}, support_radius={:e} m, stable_dt={:e} s, time={} s)",
            self.model.n_particles(),
            self.model.n_pairs(),
            self.state.active.len(),
            self.model.fixed().iter().filter(|&&f| f).count(),
            self.model.kernel(),
            self.model.support(),
            self.model.stable_dt(),
            self.state.t
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Surfaces and sampling
// ---------------------------------------------------------------------------------------------

/// A closed, manifold triangle surface [m], validated in the Rust core.
///
/// ``TriSurface(points, triangles, *, source=None)``
///
/// Parameters
/// ----------
/// points : array_like, shape (n, 3)
///     Vertex positions [m].
/// triangles : array_like, shape (m, 3)
///     Vertex indices, 0-based (any integer dtype).
/// source : str, optional
///     Where the arrays came from (a file name), prefixed to error and warning messages.
///
/// Refused with ``SurfaceError`` (naming the triangle / vertex / edge): non-finite vertices,
/// indices out of range, a repeated vertex in a triangle, a degenerate (zero-area) or duplicate
/// triangle, an open surface (an edge used by one triangle), a non-manifold one (an edge used by
/// more than two triangles, or twice in the same direction: inconsistent orientation), no
/// enclosed volume. An inward-oriented surface is reversed with a ``MeshWarning``.
#[pyclass(module = "palpate", name = "TriSurface", frozen)]
pub struct PyTriSurface {
    pub inner: TriSurface,
}

/// Apply `f` to one point (3,) -> Python scalar, or to points (n, 3) -> array (n,).
fn per_point<'py, T: numpy::Element + Copy + IntoPyObject<'py>>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    what: &str,
    f: impl Fn(&Vec3) -> T + Send + Sync,
) -> PyResult<Bound<'py, PyAny>> {
    let a = asarray(points, what)?;
    if a.shape() == [3] {
        let p = conv::vec3(points, what)?;
        return f(&p).into_bound_py_any(py);
    }
    let pts = conv::points(points, what)?;
    let out: Vec<T> = py.detach(|| pts.iter().map(|q| f(&Vec3::new(q[0], q[1], q[2]))).collect());
    Ok(Array1::from_vec(out).into_pyarray(py).into_any())
}

#[pymethods]
impl PyTriSurface {
    #[new]
    #[pyo3(signature = (points, triangles, *, source = None))]
    fn new(py: Python<'_>, points: &Bound<'_, PyAny>, triangles: &Bound<'_, PyAny>, source: Option<String>) -> PyResult<Self> {
        let p = conv::points(points, "points")?;
        let t = triangles_arg(triangles, "triangles")?;
        let (surface, warnings) = py.detach(|| TriSurface::from_arrays(&p, &t)).map_err(|e| match &source {
            Some(s) => surface_error(e.in_file(s.clone())),
            None => surface_error(e),
        })?;
        for w in warnings {
            warn(py, match &source {
                Some(s) => format!("{s}: {w}"),
                None => w.to_string(),
            })?;
        }
        Ok(PyTriSurface { inner: surface })
    }

    /// Vertex positions [m], (n, 3) (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, self.inner.points())
    }

    /// Triangles, int64 (m, 3), outward oriented (counter-clockwise seen from outside).
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, self.inner.triangles())
    }

    /// Number of vertices.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }

    /// Number of triangles.
    #[getter]
    fn n_triangles(&self) -> usize {
        self.inner.n_triangles()
    }

    /// Enclosed volume [m^3] (divergence theorem; positive).
    #[getter]
    fn volume(&self) -> f64 {
        self.inner.volume()
    }

    /// Surface area [m^2].
    #[getter]
    fn area(&self) -> f64 {
        self.inner.area()
    }

    /// ``(lo, hi)``: the axis-aligned bounding box [m] of the vertices in use, two (3,) arrays.
    #[getter]
    fn bounding_box<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let (lo, hi) = self.inner.bounding_box();
        (conv::f64s_to_py(py, &[lo.x, lo.y, lo.z]), conv::f64s_to_py(py, &[hi.x, hi.y, hi.z]))
    }

    /// Inside test for one point (3,) -> bool, or points (n, 3) -> bool array (n,).
    ///
    /// ``method="winding"`` (default): generalised winding number > 1/2 (O(triangles) per point);
    /// ``method="parity"``: parity of the +z ray's crossings (grid-accelerated, what the samplers use).
    #[pyo3(signature = (points, method = "winding"))]
    fn contains<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>, method: &str) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.inner;
        match method {
            "winding" => per_point(py, points, "points", |p| s.contains(p)),
            "parity" => per_point(py, points, "points", |p| s.contains_parity(p)),
            other => Err(PyValueError::new_err(format!("method must be 'winding' or 'parity', got {other:?}"))),
        }
    }

    /// Generalised winding number (1 inside, 0 outside, 1/2 on the surface) of one point (3,) ->
    /// float, or of points (n, 3) -> float64 array (n,).
    fn winding_number<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.inner;
        per_point(py, points, "points", |p| s.winding_number(p))
    }

    fn __len__(&self) -> usize {
        self.inner.n_triangles()
    }

    fn __repr__(&self) -> String {
        format!("TriSurface(n_vertices={}, n_triangles={}, volume={:.6e} m^3)", self.inner.n_vertices(), self.inner.n_triangles(), self.inner.volume())
    }
}

/// The ellipsoid of semi-axes ``semi_axes`` [m] centred at the origin, as a closed outward
/// surface: the octahedron cut ``subdivisions`` times into 4, projected onto the ellipsoid.
/// ``8 * 4**subdivisions`` triangles (default 4: 2048); the volume converges to 4/3 pi a b c.
#[pyfunction]
#[pyo3(signature = (semi_axes = [0.026, 0.026, 0.042], subdivisions = 4))]
pub fn ellipsoid_surface(py: Python<'_>, semi_axes: [f64; 3], subdivisions: usize) -> PyResult<PyTriSurface> {
    if !semi_axes.iter().all(|a| a.is_finite() && *a > 0.0) {
        return Err(PyValueError::new_err(format!("semi_axes must be finite and positive [m], got {semi_axes:?}")));
    }
    if subdivisions > 9 {
        return Err(PyValueError::new_err(format!("subdivisions = {subdivisions} is too many (at most 9: 2 million triangles)")));
    }
    Ok(PyTriSurface { inner: py.detach(|| mesh::ellipsoid_surface(semi_axes, subdivisions)) })
}

type Sampled<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>);

/// Particles on a cubic lattice of ``spacing`` [m] inside ``surface``: returns ``(positions (n, 3)
/// [m], masses (n,) [kg])``, each mass ``density * spacing**3`` (``density`` in kg/m^3). The lattice
/// is centred on the surface's bounding box (half a spacing inside it when the extent is a whole
/// number of spacings). ``ValueError`` for a non-positive spacing / density or a lattice too large.
#[pyfunction]
pub fn sample_inside<'py>(py: Python<'py>, surface: &Bound<'py, PyTriSurface>, spacing: f64, density: f64) -> PyResult<Sampled<'py>> {
    let s = &surface.get().inner;
    let set = py.detach(|| mesh::sample_inside(s, spacing, density)).map_err(surface_error)?;
    Ok((conv::vec3s_to_py(py, &set.positions), conv::f64s_to_py(py, &set.masses)))
}

/// Particles on a cubic lattice of ``spacing`` [m] (over ``outer``'s bounding box) inside
/// ``outer`` and not inside ``inner``: a shell. Returns ``(positions, masses)`` as
/// :func:`sample_inside`. ``SurfaceError`` if a vertex of ``inner`` is not inside ``outer``.
#[pyfunction]
pub fn sample_between<'py>(
    py: Python<'py>,
    inner: &Bound<'py, PyTriSurface>,
    outer: &Bound<'py, PyTriSurface>,
    spacing: f64,
    density: f64,
) -> PyResult<Sampled<'py>> {
    let (i, o) = (&inner.get().inner, &outer.get().inner);
    let set = py.detach(|| mesh::sample_between(i, o, spacing, density)).map_err(surface_error)?;
    Ok((conv::vec3s_to_py(py, &set.positions), conv::f64s_to_py(py, &set.masses)))
}
