//! `palpate.ParticleBody`: a meshfree solid (`palpate_core::meshfree`), its model, state and
//! workspace. Building, stepping and the timed run release the GIL.

use std::time::Instant;

use numpy::{PyArray1, PyArray2};
use palpate_core::meshfree::{Kernel, ParticleModel, ParticleModelBuilder, ParticleState, ParticleWorkspace, DEFAULT_HOURGLASS, DEFAULT_MIN_WEIGHT};
use palpate_core::Vec3;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::body::sig4;
use crate::conv::{self, PARTICLES};
use crate::errors;
use crate::material::PyMaterial;
use crate::meshfree::PyKernel;

/// A meshfree (particle) solid: the continuum law of ``Material`` on particles (paper §3.2),
/// stepped by explicit Verlet sub-steps (eq. 33) at the stable step.
///
/// ``ParticleBody(positions, masses, material, support_radius, kernel=..., fixed=None,
/// gravity=None, hourglass=..., min_relative_weight=...)``; the defaults are the core's
/// (``palpate.defaults.particles``).
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
///     Default ``Kernel.WENDLAND_C2``.
/// fixed : array_like of int, or bool mask of shape (n,), optional
///     Particles held at their rest position.
/// gravity : (3,) float, optional
///     [m/s^2], default zero.
/// hourglass : float
///     Dimensionless hourglass-control stiffness kappa (0 disables it).
/// min_relative_weight : float
///     Pair only the neighbours whose kernel weight is at least this fraction of its peak [-].
///
/// Raises ``ModelError`` naming the particle (non-finite position, non-positive mass, too few
/// neighbours to span 3D) or the parameter; ``ValueError`` / ``TypeError`` for shapes and dtypes.
///
/// All particles start active; ``active`` selects the simulated ones (the others are frozen but
/// still shape their active neighbours' deformation). Getters return copies.
///
/// ``get_state()`` / ``set_state(s)`` save and restore the state (the steps after a restore
/// repeat the original ones bit for bit: the explicit scheme keeps nothing else between steps);
/// ``copy()`` is an independent body; a body pickles (its model is rebuilt from its constructor's
/// arguments, then its state restored).
#[pyclass(module = "palpate", name = "ParticleBody")]
pub struct PyParticleBody {
    model: ParticleModel,
    state: ParticleState,
    ws: ParticleWorkspace,
    material: Py<PyMaterial>,
    /// Constructor arguments the model does not return, kept for pickling.
    gravity: Vec3,
    min_relative_weight: f64,
}

/// `state[key]`, or KeyError naming the key.
fn item<'py>(state: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    state.get_item(key)?.ok_or_else(|| crate::errors::key_error(format!("state has no {key:?} (a dict from get_state())")))
}

/// A time step [s] for `run_timed` / `substeps`: positive and finite, else ValueError.
fn check_dt(dt: f64) -> PyResult<()> {
    if dt > 0.0 && dt.is_finite() {
        Ok(())
    } else {
        Err(crate::errors::param_error_from(format!("dt = {dt} s must be positive and finite")))
    }
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
    #[pyo3(signature = (positions, masses, material, support_radius, kernel = PyKernel::from(Kernel::default()), fixed = None, gravity = None, hourglass = DEFAULT_HOURGLASS, min_relative_weight = DEFAULT_MIN_WEIGHT))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
        masses: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = conv::arg)] material: Bound<'_, PyMaterial>,
        #[pyo3(from_py_with = conv::arg)] support_radius: f64,
        #[pyo3(from_py_with = conv::arg)] kernel: PyKernel,
        fixed: Option<&Bound<'_, PyAny>>,
        gravity: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = conv::arg)] hourglass: f64,
        #[pyo3(from_py_with = conv::arg)] min_relative_weight: f64,
    ) -> PyResult<Self> {
        let p = conv::points_vec3(positions, "positions")?;
        let n = p.len();
        let m = conv::reals(masses, "masses", n, "(one per particle)")?;
        let fixed = match fixed {
            Some(f) if !f.is_none() => conv::indices(f, "fixed", n, PARTICLES, false)?,
            _ => Vec::new(),
        };
        let gravity = match gravity {
            Some(g) if !g.is_none() => conv::vec3(g, "gravity")?,
            _ => Vec3::zeros(),
        };
        let builder = ParticleModelBuilder::new(p, m, material.get().inner, support_radius)
            .kernel(kernel.into())
            .fixed_particles(fixed)
            .gravity(gravity)
            .hourglass(hourglass)
            .min_relative_weight(min_relative_weight);
        let model = errors::guard("ParticleBody", || py.detach(|| builder.build()).map_err(errors::model_error))?;
        let state = ParticleState::rest(&model);
        let ws = ParticleWorkspace::new(&model);
        Ok(PyParticleBody { model, state, ws, material: material.unbind(), gravity, min_relative_weight })
    }

    /// Advance ``n`` steps of ``dt`` [s] with the current external forces (GIL released). Each
    /// step takes ``substeps(dt)`` explicit sub-steps.
    ///
    /// Returns a dict: ``steps``, ``substeps`` (per step), ``substep_dt`` [s].
    /// Raises ``StepError`` if a step fails; the steps before it are kept and the body is left as
    /// it was before the failing step.
    #[pyo3(signature = (n = errors::Int::Fits(1), dt = 1e-3), text_signature = "($self, n=1, dt=1e-3)")]
    fn step<'py>(mut slf: PyRefMut<'py, Self>, py: Python<'py>, n: errors::Int, #[pyo3(from_py_with = conv::arg)] dt: f64) -> PyResult<Bound<'py, PyDict>> {
        let n = errors::count(n, "n")?;
        if !(dt > 0.0 && dt.is_finite()) {
            return Err(errors::step_error(palpate_core::StepError::BadTimeStep(dt), ""));
        }
        let this = &mut *slf;
        let (model, state, ws) = (&this.model, &mut this.state, &mut this.ws);
        let mut ctrl_c = errors::CtrlC::new();
        errors::guard("ParticleBody.step", || {
            py.detach(|| {
                (0..n).try_for_each(|k| {
                    // Ctrl-C between steps: the body keeps the steps it took.
                    if k > 0 && ctrl_c.poll() {
                        return Err((k, None));
                    }
                    palpate_core::meshfree::step(model, state, ws, dt).map(|_| ()).map_err(|e| (k, Some(e)))
                })
            })
            .map_err(|(k, e)| match e {
                Some(e) => errors::step_error(e, &format!("in step {} of {n}", k + 1)),
                None => ctrl_c.finish((), |_| errors::param_error_from("interrupted")),
            })
        })?;
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
    /// early, else None). Stops early when a step fails, the summed wall time exceeds
    /// ``max_wall_s`` [s], or the per-tick record would outgrow the memory budget
    /// (``PALPATE_MAX_MEMORY``).
    #[pyo3(signature = (ticks, dt = 1e-3, max_wall_s = None))]
    fn run_timed<'py>(
        mut slf: PyRefMut<'py, Self>,
        py: Python<'py>,
        ticks: errors::Int,
        #[pyo3(from_py_with = conv::arg)] dt: f64,
        #[pyo3(from_py_with = conv::arg)] max_wall_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let ticks = errors::count(ticks, "ticks")?;
        check_dt(dt)?;
        crate::body::check_run_limits(None, max_wall_s)?;
        let this = &mut *slf;
        let (model, state, ws) = (&this.model, &mut this.state, &mut this.ws);
        let substeps = model.substeps(dt);
        // The per-tick record grows as ticks are taken (reserving 1e11 up front aborted).
        let run = errors::guard("ParticleBody.run_timed", || {
            Ok(py.detach(|| {
            let mut out = TimedRun { tick_wall: Vec::with_capacity(ticks.min(1 << 16)), substeps, substep_dt: dt / substeps as f64, error: None };
            let mut total = 0.0;
            for k in 0..ticks {
                // Before the record doubles: would it fit the memory budget? (Stop, not abort.)
                if out.tick_wall.len() == out.tick_wall.capacity() {
                    if let Err(e) = palpate_core::limits::check("the per-tick record", 2.0 * out.tick_wall.capacity().max(1) as f64, 8.0) {
                        out.error = Some(format!("stopped after {k} of {ticks} ticks: the per-tick record would grow past the memory budget of {} ({}; set PALPATE_MAX_MEMORY to change it, or run fewer ticks at a time)", palpate_core::limits::human_bytes(e.budget as f64), e.budget_source));
                        break;
                    }
                }
                let t0 = Instant::now();
                let r = palpate_core::meshfree::step(model, state, ws, dt);
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
        }))
        })?;
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
        self.state.f_ext = conv::forces(forces, "forces", self.model.n_particles())?;
        Ok(())
    }

    /// The state as a dict of copies: ``positions`` [m], ``velocities`` [m/s] (half-step, Verlet)
    /// and ``forces`` [N], each (n, 3) float64, world frame; ``time`` [s]; ``active``, int64 (k,).
    /// Plain Python and numpy values: it pickles.
    fn get_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("positions", conv::vec3s_to_py(py, &self.state.x))?;
        d.set_item("velocities", conv::vec3s_to_py(py, &self.state.v))?;
        d.set_item("forces", conv::vec3s_to_py(py, &self.state.f_ext))?;
        d.set_item("time", self.state.t)?;
        d.set_item("active", conv::usizes_to_py(py, &self.state.active))?;
        Ok(d)
    }

    /// Restore a state from :meth:`get_state` (of this body or one built the same way): the next
    /// steps repeat those that followed it bit for bit. Raises ``KeyError`` for a missing entry,
    /// ``ValueError`` for a wrong shape, a non-finite value or a bad index; the body is unchanged
    /// then.
    fn set_state(&mut self, #[pyo3(from_py_with = conv::arg)] state: Bound<'_, PyDict>) -> PyResult<()> {
        let n = self.model.n_particles();
        let x = conv::vec3s(&item(&state, "positions")?, "positions", n, true)?;
        let v = conv::vec3s(&item(&state, "velocities")?, "velocities", n, true)?;
        let f_ext = conv::forces(&item(&state, "forces")?, "forces", n)?;
        let t: f64 = conv::arg(&item(&state, "time")?)?;
        if !t.is_finite() {
            return Err(crate::errors::param_error_from(format!("time = {t} s must be finite")));
        }
        let active = conv::indices(&item(&state, "active")?, "active", n, PARTICLES, true)?;
        self.state = ParticleState { x, v, t, f_ext, active };
        Ok(())
    }

    /// An independent copy: the same model (shared, immutable material object) and state.
    fn copy(&self, py: Python<'_>) -> PyParticleBody {
        PyParticleBody {
            model: self.model.clone(),
            state: self.state.clone(),
            ws: self.ws.clone(),
            material: self.material.clone_ref(py),
            gravity: self.gravity,
            min_relative_weight: self.min_relative_weight,
        }
    }

    fn __copy__(&self, py: Python<'_>) -> PyParticleBody {
        self.copy(py)
    }

    fn __deepcopy__(&self, py: Python<'_>, _memo: &Bound<'_, PyAny>) -> PyParticleBody {
        self.copy(py)
    }

    /// Gravitational acceleration [m/s^2], (3,), world frame.
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::vec3_to_py(py, self.gravity)
    }

    /// The neighbour cut-off: pairs whose kernel weight is below this fraction of its peak are
    /// left out [-].
    #[getter]
    fn min_relative_weight(&self) -> f64 {
        self.min_relative_weight
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
        self.state.active = conv::indices(active, "active", self.model.n_particles(), PARTICLES, true)?;
        Ok(())
    }

    /// Indices of the fixed particles, int64 (k,), ascending.
    #[getter]
    fn fixed<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::flagged_to_py(py, self.model.fixed())
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
    fn substeps(&self, #[pyo3(from_py_with = conv::arg)] dt: f64) -> PyResult<usize> {
        check_dt(dt)?;
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
    fn neighbours<'py>(&self, py: Python<'py>, i: errors::Int) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let i = errors::index(i, self.model.n_particles(), "i", "particles")?;
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
        conv::vec3_to_py(py, self.model.momentum(&self.state.v))
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
        let m = self.material.get().inner;
        format!(
            "<palpate.ParticleBody: {} particles ({} active, {} fixed), {} pairs; {} kernel, support radius {} m; E = {} Pa, nu = {}, {} kg/m^3; stable dt {} s; t = {} s>",
            self.model.n_particles(),
            self.state.active.len(),
            self.model.fixed().iter().filter(|&&f| f).count(),
            self.model.n_pairs(),
            kernel_words(self.model.kernel()),
            sig4(self.model.support()),
            sig4(m.young()),
            sig4(m.poisson()),
            sig4(m.density()),
            sig4(self.model.stable_dt()),
            self.state.t
        )
    }
}

/// The kernel's name in palpate's words (`palpate.Kernel`).
fn kernel_words(k: Kernel) -> &'static str {
    match k {
        Kernel::WendlandC2 => "Wendland C2",
        Kernel::CubicSpline => "cubic spline",
        Kernel::LinearLennardJones => "linear Lennard-Jones",
    }
}
