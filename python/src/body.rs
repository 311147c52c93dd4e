//! `palpate.Body`: the FEM body, a compiled model with its state and workspace (`palpate_core::{Model,
//! State, Workspace}`, the FEM body of `crates/palpate-core/src/fem/`; `step` from `integrate/`).
//! Stepping, static solves and the timed probe run release the GIL.

use std::time::Instant;

use numpy::{PyArray1, PyArray2};
use palpate_core::integrate::{indent_with, static_solve_with, IndentOptions, Indenter, StaticOptions};
use palpate_core::probe::{self, ProbeLoad, ProbeOptions, Ramp, StepClock, StepTotals};
use palpate_core::{step, Model, ModelBuilder, Order, State, StepMemory, Vec3, Workspace};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::conv;
use crate::errors;
use crate::integrator::{integrator_from_py, integrator_to_py};
use crate::material::PyMaterial;
use crate::mesh::PyTetMesh;

/// A deformable body: mesh + material + fixed nodes + gravity + integrator, and its state.
///
/// ``Body(mesh, material, fixed=None, gravity=(0, 0, 0), integrator=None, *, order=1)``
///
/// Parameters
/// ----------
/// mesh : TetMesh
///     Rest geometry [m].
/// material : Material
/// fixed : array_like of int, shape (k,), or bool mask of shape (n,), optional
///     Nodes held at their rest position (zero velocity).
/// gravity : (3,) float
///     Gravitational acceleration [m/s^2], world frame.
/// integrator : SemiImplicit | BackwardEuler, optional
///     Default ``BackwardEuler()``: quasi-Newton minimisation of the incremental potential,
///     stable at any press, one iteration (one solve with the rest matrix, factorised once per
///     dt) at small deformation.
/// order : int, 1 or 2
///     The elements' polynomial degree. 1 (default): linear tets, the paper's, whose nodes are
///     the mesh's vertices. 2: quadratic (10-node) tets, whose nodes are the mesh's vertices
///     followed by one node per edge (``edges``: node ``mesh.n_nodes + k`` sits at the midpoint
///     of ``edges[k]`` at rest). Linear tets lock in bending: a wall one or two elements across
///     is several times too stiff, where quadratic ones are within a few percent (VALIDATION.md);
///     a quadratic tet costs about ten linear ones. The semi-implicit integrator is for linear
///     tets only. ``fixed`` indexes the body's nodes; an edge node whose two vertices are fixed
///     is fixed too.
///
/// All per-node arrays are (n, 3) float64 in SI units, world frame; getters return copies.
///
/// ``get_state()`` / ``set_state(s)`` save and restore the state with the integrator's memory (the
/// steps after a restore repeat the original ones bit for bit); ``copy()`` is an independent body;
/// a body pickles (its model is rebuilt from mesh, material, fixed nodes, gravity and integrator,
/// then its state restored). Changing ``dt`` reuses the factorisations of the recently used
/// ``dt`` (``prepare``).
#[pyclass(module = "palpate", name = "Body")]
pub struct PyBody {
    model: Model,
    state: State,
    ws: Workspace,
    mesh: Py<PyTetMesh>,
    material: Py<PyMaterial>,
}

impl PyBody {
    /// The compiled model (the haptic loop rebuilds it with its own material).
    pub(crate) fn model(&self) -> &Model {
        &self.model
    }

    /// `n` steps; `interrupted` is asked before each (the steps taken before it said stop are
    /// kept: `Err((k, None))`).
    fn run_steps(&mut self, n: usize, dt: f64, interrupted: &mut dyn FnMut() -> bool) -> Result<StepTotals, (usize, Option<palpate_core::StepError>)> {
        let mut tot = StepTotals::default();
        for k in 0..n {
            if k > 0 && interrupted() {
                return Err((k, None));
            }
            let r = step(&self.model, &mut self.state, &mut self.ws, dt).map_err(|e| (k, Some(e)))?;
            tot.add(&r);
        }
        Ok(tot)
    }
}

/// A wall clock for `run_probe` (the core has none: it is passed in).
struct WallClock(Instant);

impl StepClock for WallClock {
    fn now(&mut self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }
}

/// One probe load from Python values, its ramp starting at `start` [s].
fn py_load(n: usize, nodes: Vec<usize>, total_force: &Bound<'_, PyAny>, ramp_time: f64, start: f64) -> PyResult<ProbeLoad> {
    let total = conv::force(total_force, "total_force")?;
    if !(ramp_time >= 0.0 && ramp_time.is_finite()) {
        return Err(crate::errors::param_error_from(format!("ramp_time = {ramp_time} s must be finite and >= 0")));
    }
    ProbeLoad::new(n, nodes, total, Ramp { start, duration: ramp_time }).map_err(|e| crate::errors::param_error_from(format!("nodes: {e}")))
}

impl PyBody {
    /// `probe::run_probe` timed by a wall clock, GIL released; its result as a dict.
    fn run_timed<'py>(
        &mut self,
        py: Python<'py>,
        loads: &[ProbeLoad],
        steps: usize,
        dt: f64,
        stable_limit: f64,
        max_wall_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        if steps == 0 {
            return Err(crate::errors::param_error_from("steps must be at least 1"));
        }
        check_run_limits(Some(stable_limit), max_wall_s)?;
        let opts = ProbeOptions { max_wall_s, ..ProbeOptions::new(steps, dt, stable_limit) };
        let run = errors::guard("Body.run_probe", || {
            Ok(py.detach(|| {
                let mut clock = WallClock(Instant::now());
                probe::run_probe(&self.model, &mut self.state, &mut self.ws, loads, &opts, &mut clock)
            }))
        })?;
        let d = PyDict::new(py);
        d.set_item("steps", run.steps)?;
        d.set_item("wall_s", run.wall_s)?;
        d.set_item("stable", run.stable)?;
        d.set_item("max_disp_m", run.max_disp)?;
        d.set_item("probe_disp_avg_m", run.probe_disp_avg)?;
        d.set_item("mean_disp", conv::vec3s_to_py(py, &run.mean_disp))?;
        d.set_item("probe_disp", conv::f64s_to_py(py, &run.probe_disp))?;
        let step_us: Vec<f64> = run.step_s.iter().map(|s| s * 1e6).collect();
        d.set_item("step_us", conv::f64s_to_py(py, &step_us))?;
        let t = &run.totals;
        d.set_item("iterations_mean", t.mean_iterations())?;
        d.set_item("iterations_max", t.max_iterations)?;
        d.set_item("evaluations", t.evaluations)?;
        d.set_item("factorizations", t.factorizations)?;
        d.set_item("inverted_max", t.max_inverted)?;
        d.set_item("unconverged_steps", t.unconverged)?;
        d.set_item("error", run.stop.map(|s| s.to_string()))?;
        Ok(d)
    }
}

/// A run's `stable_limit` [m] (positive; infinity: no limit) and `max_wall_s` [s] (>= 0, 0
/// stopping after the first step; None or infinity: no cap). NaN compared false everywhere: a NaN cap was never reached and a
/// NaN limit called every run unstable, without a word (issue 35 item 6).
pub(crate) fn check_run_limits(stable_limit: Option<f64>, max_wall_s: Option<f64>) -> PyResult<()> {
    if let Some(s) = stable_limit {
        if s.is_nan() || s <= 0.0 {
            return Err(crate::errors::param_error_from(format!("stable_limit = {s} m must be positive (inf for no limit)")));
        }
    }
    if let Some(w) = max_wall_s {
        if w.is_nan() || w < 0.0 {
            return Err(crate::errors::param_error_from(format!("max_wall_s = {w} s must be >= 0 (0: stop after the first step; None for no cap)")));
        }
    }
    Ok(())
}

/// `state[key]`, or KeyError naming the key.
fn item<'py>(state: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    state.get_item(key)?.ok_or_else(|| crate::errors::key_error(format!("state has no {key:?} (a dict from get_state())")))
}

/// `x` to 4 significant digits, printed shortest (0.4, not 0.39999999999999997), for reprs.
pub(crate) fn sig4(x: f64) -> String {
    format!("{:.3e}", x).parse::<f64>().map(|r| r.to_string()).unwrap_or_else(|_| x.to_string())
}

/// The integrator's name in palpate's words (`palpate.SemiImplicit`, `palpate.BackwardEuler`).
pub(crate) fn integrator_words(i: palpate_core::Integrator) -> String {
    use palpate_core::Integrator as I;
    match i {
        I::SemiImplicit { .. } => "semi-implicit".into(),
        I::BackwardEulerLinear => "backward Euler, linearised".into(),
        I::BackwardEulerQuasiNewton { .. } => "backward Euler, quasi-Newton".into(),
        I::BackwardEulerNewton { .. } => "backward Euler, Newton".into(),
    }
}

#[pymethods]
impl PyBody {
    #[new]
    #[pyo3(signature = (mesh, material, fixed = None, gravity = None, integrator = None, *, order = errors::Int::Fits(1)), text_signature = "(mesh, material, fixed=None, gravity=None, integrator=None, *, order=1)")]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = conv::arg)] mesh: Bound<'_, PyTetMesh>,
        #[pyo3(from_py_with = conv::arg)] material: Bound<'_, PyMaterial>,
        fixed: Option<&Bound<'_, PyAny>>,
        gravity: Option<&Bound<'_, PyAny>>,
        integrator: Option<&Bound<'_, PyAny>>,
        order: errors::Int,
    ) -> PyResult<Self> {
        let order = match order {
            errors::Int::Fits(1) => Order::Linear,
            errors::Int::Fits(2) => Order::Quadratic,
            other => return Err(errors::param_error_from(format!("order = {other} must be 1 (linear tets) or 2 (quadratic tets)"))),
        };
        let n = match order {
            Order::Linear => mesh.get().inner.n_nodes(),
            Order::Quadratic => mesh.get().inner.n_nodes() + mesh.get().inner.edges().len(),
        };
        let fixed = match fixed {
            Some(f) if !f.is_none() => conv::indices(f, "fixed", n, conv::NODES, false)?,
            _ => Vec::new(),
        };
        let gravity = match gravity {
            Some(g) if !g.is_none() => conv::vec3(g, "gravity")?,
            _ => Vec3::zeros(),
        };
        let integrator = integrator_from_py(integrator)?;
        let builder = ModelBuilder::new(mesh.get().inner.clone(), material.get().inner)
            .fixed_nodes(fixed)
            .gravity(gravity)
            .integrator(integrator)
            .order(order);
        let model = errors::guard("Body", || py.detach(|| builder.build()).map_err(errors::model_error))?;
        let state = State::rest(&model);
        let ws = Workspace::new(&model);
        Ok(PyBody { model, state, ws, mesh: mesh.unbind(), material: material.unbind() })
    }

    /// Advance ``n`` steps of ``dt`` [s] with the current external forces (GIL released).
    ///
    /// Returns a dict: ``steps``; ``iterations`` (summed over the steps) and ``iterations_max``;
    /// ``evaluations`` (force evaluations, line-search trials included); ``factorizations``
    /// (sparse factorisations: the first step at a new dt, refreshes of the quasi-Newton initial
    /// Hessian); ``solves`` (solves with
    /// the factorised matrix); ``unconverged_steps`` (steps that hit ``max_iterations``);
    /// ``max_residual`` (relative gradient of the incremental potential); ``inverted_max``
    /// (elements with det F <= 0 after a step, the most over the steps); ``inverted`` and
    /// ``potential_change`` [J] of the last step (the change of the incremental potential, <= 0
    /// for the minimising solvers).
    ///
    /// Raises ``StepError`` if a step fails (bad dt, non-finite force or result); the steps
    /// before it are kept and the body is left as it was before the failing step.
    ///
    /// Other Python threads run meanwhile; they cannot use this body until the call returns
    /// (doing so raises ``RuntimeError: Already borrowed``).
    #[pyo3(signature = (n = errors::Int::Fits(1), dt = 1e-3), text_signature = "($self, n=1, dt=1e-3)")]
    fn step<'py>(mut slf: PyRefMut<'py, Self>, py: Python<'py>, n: errors::Int, #[pyo3(from_py_with = conv::arg)] dt: f64) -> PyResult<Bound<'py, PyDict>> {
        let n = errors::count(n, "n")?;
        let this = &mut *slf;
        let mut ctrl_c = errors::CtrlC::new();
        let tot = errors::guard("Body.step", || {
            py.detach(|| this.run_steps(n, dt, &mut || ctrl_c.poll())).map_err(|(k, e)| match e {
                Some(e) => errors::step_error(e, &format!("in step {} of {n}", k + 1)),
                // Ctrl-C: the body keeps the k steps it took.
                None => ctrl_c.finish((), |_| errors::param_error_from("interrupted")),
            })
        })?;
        let d = PyDict::new(py);
        d.set_item("steps", tot.steps)?;
        d.set_item("iterations", tot.iterations)?;
        d.set_item("iterations_max", tot.max_iterations)?;
        d.set_item("evaluations", tot.evaluations)?;
        d.set_item("factorizations", tot.factorizations)?;
        d.set_item("solves", tot.solves)?;
        d.set_item("unconverged_steps", tot.unconverged)?;
        d.set_item("max_residual", tot.max_residual)?;
        d.set_item("inverted_max", tot.max_inverted)?;
        d.set_item("inverted", tot.last.inverted)?;
        d.set_item("potential_change", tot.last.potential_change)?;
        Ok(d)
    }

    /// Set the external force on every node [N], array (n, 3); held until changed.
    fn set_forces(&mut self, forces: &Bound<'_, PyAny>) -> PyResult<()> {
        let f = conv::forces(forces, "forces", self.model.n_nodes())?;
        errors::warn_fixed_load(forces.py(), self.model.fixed(), f.iter().map(|v| v.norm()).enumerate(), "set_forces")?;
        self.state.f_ext = f;
        Ok(())
    }

    /// External force on every node [N], (n, 3) (a copy).
    #[getter]
    fn forces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.f_ext)
    }

    /// Node positions [m], (n, 3) (a copy).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.x)
    }

    /// Node velocities [m/s], (n, 3) (a copy).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.v)
    }

    /// Displacements from the rest positions [m], (n, 3).
    #[getter]
    fn displacements<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.displacements(&self.model))
    }

    /// Simulated time [s].
    #[getter]
    fn time(&self) -> f64 {
        self.state.t
    }

    /// Number of nodes n.
    #[getter]
    fn n_nodes(&self) -> usize {
        self.model.n_nodes()
    }

    /// Number of tets.
    #[getter]
    fn n_tets(&self) -> usize {
        self.model.n_tets()
    }

    /// The elements' polynomial degree: 1 (linear tets) or 2 (quadratic).
    #[getter]
    fn order(&self) -> u8 {
        match self.model.order() {
            Order::Linear => 1,
            Order::Quadratic => 2,
        }
    }

    /// With quadratic tets, the two vertices of each edge node, int64 (e, 2): node
    /// ``mesh.n_nodes + k`` is edge ``k``'s (at its midpoint at rest); (0, 2) for linear tets.
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, self.model.edges())
    }

    /// The rest mesh.
    #[getter]
    fn mesh(&self, py: Python<'_>) -> Py<PyTetMesh> {
        self.mesh.clone_ref(py)
    }

    /// The material.
    #[getter]
    fn material(&self, py: Python<'_>) -> Py<PyMaterial> {
        self.material.clone_ref(py)
    }

    /// The integrator (a SemiImplicit or BackwardEuler object).
    #[getter]
    fn integrator(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        integrator_to_py(py, self.model.integrator())
    }

    /// Indices of the fixed nodes, int64 (k,), ascending.
    #[getter]
    fn fixed<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::flagged_to_py(py, self.model.fixed())
    }

    /// Lumped node masses [kg], (n,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::f64s_to_py(py, self.model.masses())
    }

    /// Gravitational acceleration [m/s^2], (3,).
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::vec3_to_py(py, self.model.gravity())
    }

    /// Elastic strain energy of the current positions [J].
    fn strain_energy(&self) -> f64 {
        self.model.strain_energy(&self.state.x)
    }

    /// Per-element fields of the current positions, for output: a dict of (m,) float64 arrays,
    /// ``von_mises`` [Pa] (von Mises equivalent of the elastic Cauchy stress; of the Kirchhoff
    /// stress for an inverted element), ``energy_density`` [J/m^3] (strain energy per rest
    /// volume), ``det_f`` [-] (volume ratio; <= 0: inverted).
    fn element_fields<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = errors::guard("Body.element_fields", || Ok(py.detach(|| self.model.element_fields(&self.state.x))))?;
        let d = PyDict::new(py);
        d.set_item("von_mises", conv::f64s_to_py(py, &f.von_mises))?;
        d.set_item("energy_density", conv::f64s_to_py(py, &f.energy_density))?;
        d.set_item("det_f", conv::f64s_to_py(py, &f.det_f))?;
        Ok(d)
    }

    /// Kinetic energy of the current velocities [J].
    fn kinetic_energy(&self) -> f64 {
        self.model.kinetic_energy(&self.state.v)
    }

    /// Back to rest: rest positions, zero velocity, time 0, no external force.
    fn reset(&mut self) {
        self.state = State::rest(&self.model);
    }

    /// Static equilibrium under per-node forces [N] (n, 3) (default: the current external forces)
    /// and gravity, by Newton's method on the full nonlinear forces (GIL released).
    ///
    /// Returns the equilibrium positions [m], (n, 3). The body's state is not changed.
    /// ``tolerance`` is on max |residual| relative to max |applied force|; ``load_steps`` > 1
    /// applies the load in increments (for large loads). ``None`` takes the core's default
    /// (``StaticOptions::default()``, as ``palpate.defaults.static_solve``).
    /// Raises ``SolveError`` if Newton does not converge; Ctrl-C (``KeyboardInterrupt``) stops
    /// it between Newton iterations.
    #[pyo3(signature = (forces = None, *, max_iterations = None, tolerance = None, load_steps = None))]
    fn static_solve<'py>(
        &self,
        py: Python<'py>,
        forces: Option<&Bound<'py, PyAny>>,
        max_iterations: Option<errors::Int>,
        #[pyo3(from_py_with = conv::arg)] tolerance: Option<f64>,
        load_steps: Option<errors::Int>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (max_iterations, load_steps) = (errors::count_opt(max_iterations, "max_iterations")?, errors::count_opt(load_steps, "load_steps")?);
        let d = StaticOptions::default();
        let (max_iterations, tolerance, load_steps) =
            (max_iterations.unwrap_or(d.max_iterations), tolerance.unwrap_or(d.tolerance), load_steps.unwrap_or(d.load_steps));
        let f = match forces {
            Some(f) if !f.is_none() => conv::forces(f, "forces", self.model.n_nodes())?,
            _ => self.state.f_ext.clone(),
        };
        if !(tolerance > 0.0 && tolerance.is_finite()) {
            return Err(crate::errors::param_error_from(format!("tolerance = {tolerance} must be positive")));
        }
        // 0 increments was taken as 1 without a word (issue 35 item 6).
        if load_steps == 0 {
            return Err(crate::errors::param_error_from(
                "load_steps = 0: the load is applied in at least 1 increment (give 1 or more, or None for the default)",
            ));
        }
        let opts = StaticOptions { max_iterations, tolerance, load_steps };
        let model = &self.model;
        let mut ctrl_c = errors::CtrlC::new();
        let sol = errors::guard("Body.static_solve", || {
            py.detach(|| static_solve_with(model, &f, &opts, &mut || ctrl_c.poll()))
                .map_err(|e| ctrl_c.finish(e, errors::solve_error))
        })?;
        Ok(conv::vec3s_to_py(py, &sol.x))
    }

    /// Static sphere indentation (GIL released): the reference of ``palpate validate
    /// indentation`` (``palpate_core::integrate::indent``).
    ///
    /// A rigid frictionless sphere of ``radius`` [m] moves from ``start`` [m] (outside the body)
    /// along the unit ``direction`` (into the body); at each of ``travels`` [m] beyond its first
    /// contact (increasing) the body is brought to static equilibrium (Newton on the full
    /// nonlinear forces, the body's fixed nodes, no gravity or external force) under a penalty
    /// per unit area ``stiffness`` [N/m^3] (default ``1000 E / radius``) integrated over sample
    /// points of the boundary triangles ``sample_spacing`` [m] apart (default ``radius / 12``), so
    /// the sphere meets the surface over its whole footprint. ``max_increment`` [m] (default
    /// ``radius / 20``) bounds the travel between equilibria; ``tolerance`` is on the residual
    /// relative to the largest nodal contact force. The body's state is not changed.
    ///
    /// Returns a dict of arrays over the travels: ``travel`` [m]; ``force`` (k, 3) [N] on the
    /// sphere, world frame; ``force_along`` [N], its component along ``-direction`` (the push
    /// back, positive); ``penetration`` [m], the deepest sample; ``indentation`` [m], travel
    /// minus penetration (how far the surface was pushed in); ``contact_samples``,
    /// ``contact_area`` [m^2], ``iterations``, ``factorisations``; ``positions`` (k, n, 3) [m];
    /// ``contact_forces`` (k, n, 3) [N], the contact's nodal forces on the body.
    /// Raises ``SolveError`` if an equilibrium is not reached, ``ParameterError`` on bad input.
    #[pyo3(signature = (start, direction, radius, travels, *, stiffness = None, max_increment = None, sample_spacing = None, tolerance = None))]
    #[allow(clippy::too_many_arguments)]
    fn indent<'py>(
        &self,
        py: Python<'py>,
        start: &Bound<'py, PyAny>,
        direction: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = conv::arg)] radius: f64,
        travels: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = conv::arg)] stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] max_increment: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] sample_spacing: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] tolerance: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let start = conv::vec3(start, "start")?;
        let direction = conv::vec3(direction, "direction")?;
        let norm = direction.norm();
        if norm == 0.0 {
            return Err(crate::errors::param_error_from("direction must not be zero"));
        }
        let (travels, _) = conv::reals_nd(travels, "travels")?;
        let d = IndentOptions::default();
        let positive = |v: Option<f64>, name: &str, default: f64| -> PyResult<f64> {
            match v {
                None => Ok(default),
                Some(x) if x > 0.0 && x.is_finite() => Ok(x),
                Some(x) => Err(crate::errors::param_error_from(format!("{name} = {x} must be positive and finite"))),
            }
        };
        let opts = IndentOptions {
            stiffness: positive(stiffness, "stiffness", d.stiffness)?,
            max_increment: positive(max_increment, "max_increment", d.max_increment)?,
            sample_spacing: positive(sample_spacing, "sample_spacing", d.sample_spacing)?,
            tolerance: positive(tolerance, "tolerance", d.tolerance)?,
            ..d
        };
        let ind = Indenter { start, direction: direction / norm, radius };
        let model = &self.model;
        let mut ctrl_c = errors::CtrlC::new();
        let pts = errors::guard("Body.indent", || {
            py.detach(|| indent_with(model, &ind, &travels, &opts, &mut || ctrl_c.poll()))
                .map_err(|e| ctrl_c.finish(e, errors::solve_error))
        })?;
        let out = PyDict::new(py);
        let col = |f: &dyn Fn(&palpate_core::integrate::IndentPoint) -> f64| -> Vec<f64> { pts.iter().map(f).collect() };
        out.set_item("travel", conv::f64s_to_py(py, &col(&|p| p.travel)))?;
        let forces: Vec<Vec3> = pts.iter().map(|p| p.force).collect();
        out.set_item("force", conv::vec3s_to_py(py, &forces))?;
        out.set_item("force_along", conv::f64s_to_py(py, &col(&|p| -p.force.dot(&ind.direction))))?;
        out.set_item("penetration", conv::f64s_to_py(py, &col(&|p| p.penetration)))?;
        out.set_item("indentation", conv::f64s_to_py(py, &col(&|p| p.indentation)))?;
        out.set_item("contact_samples", conv::f64s_to_py(py, &col(&|p| p.contact_samples as f64)))?;
        out.set_item("contact_area", conv::f64s_to_py(py, &col(&|p| p.contact_area)))?;
        out.set_item("iterations", conv::f64s_to_py(py, &col(&|p| p.iterations as f64)))?;
        out.set_item("factorisations", conv::f64s_to_py(py, &col(&|p| p.factorisations as f64)))?;
        let n = model.n_nodes();
        let flat: Vec<f64> = pts.iter().flat_map(|p| p.x.iter().flat_map(|v| [v.x, v.y, v.z])).collect();
        out.set_item("positions", conv::f64s_nd_to_py(py, flat, &[pts.len(), n, 3]))?;
        let flat: Vec<f64> = pts.iter().flat_map(|p| p.contact_forces.iter().flat_map(|v| [v.x, v.y, v.z])).collect();
        out.set_item("contact_forces", conv::f64s_nd_to_py(py, flat, &[pts.len(), n, 3]))?;
        Ok(out)
    }

    /// The benchmark's probe run, timed in Rust (GIL released).
    ///
    /// For step k = 0 .. steps-1 the nodes ``nodes`` each carry ``total_force / len(nodes)`` [N]
    /// scaled by ``min(1, (k+1) dt / ramp_time)`` (the ramp starts at this call and the load of a
    /// step is its value at the step's end, the one convention of ``palpate_core::probe``; every
    /// other node carries no external force), then one step of ``dt`` [s] is taken. Only the step calls are
    /// timed (``std::time::Instant``); the bookkeeping between them is not.
    ///
    /// Returns a dict:
    ///   ``steps`` completed; ``wall_s`` [s] summed over the step calls; ``stable`` (every position
    ///   finite and max |u| < ``stable_limit`` [m] throughout); ``max_disp_m`` max over nodes and
    ///   steps of |u|; ``probe_disp_avg_m`` mean over the second half of the steps of the loaded
    ///   nodes' mean |u|; ``mean_disp`` (n, 3) the displacement field averaged over steps
    ///   k >= steps // 2 [m]; ``probe_disp`` (steps,) the loaded nodes' mean |u| after each step
    ///   [m]; ``step_us`` (steps,) the time of each step call [us]; ``iterations_mean``,
    ///   ``iterations_max`` (nonlinear iterations per step), ``evaluations`` (force evaluations in
    ///   all), ``factorizations``, ``inverted_max`` (most elements with det F <= 0 after a step), ``unconverged_steps``;
    ///   ``error`` (why the run stopped early, else None).
    /// The run stops early if a step fails, max |u| exceeds 1 m, or the timed wall-clock exceeds
    /// ``max_wall_s`` [s] (then ``stable`` covers the steps that ran).
    #[pyo3(signature = (nodes, total_force, ramp_time, steps, dt = 1e-3, stable_limit = 0.02, max_wall_s = None))]
    #[allow(clippy::too_many_arguments)]
    fn run_probe<'py>(
        mut slf: PyRefMut<'py, Self>,
        py: Python<'py>,
        nodes: &Bound<'py, PyAny>,
        total_force: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = conv::arg)] ramp_time: f64,
        steps: errors::Int,
        #[pyo3(from_py_with = conv::arg)] dt: f64,
        #[pyo3(from_py_with = conv::arg)] stable_limit: f64,
        #[pyo3(from_py_with = conv::arg)] max_wall_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let steps = errors::count(steps, "steps")?;
        let this = &mut *slf;
        let n = this.model.n_nodes();
        let loaded = conv::node_indices(nodes, "nodes", n)?;
        errors::warn_fixed_load(py, this.model.fixed(), loaded.iter().map(|&i| (i, 1.0)), "run_probe")?;
        let load = py_load(n, loaded, total_force, ramp_time, this.state.t)?;
        this.run_timed(py, &[load], steps, dt, stable_limit, max_wall_s)
    }

    /// Steps under several loads, as ``run_probe`` under one (GIL released): the scene runner's
    /// loop. ``loads`` is a sequence of ``(nodes, total_force, ramp_time)``: ``total_force`` [N]
    /// (3,) shared evenly by ``nodes``, ramped linearly over ``ramp_time`` [s] from
    /// ``ramp_start`` [s] (default: the body's time now), the load of each step taken at the
    /// step's end; every other node carries no external force. Returns ``run_probe``'s dict
    /// (``probe_disp`` over all loaded nodes; ``stable`` against ``stable_limit`` [m]).
    #[pyo3(signature = (loads, steps, dt = 1e-3, *, ramp_start = None, stable_limit = f64::INFINITY, max_wall_s = None))]
    #[allow(clippy::too_many_arguments)]
    fn run_loads<'py>(
        mut slf: PyRefMut<'py, Self>,
        py: Python<'py>,
        #[pyo3(from_py_with = conv::arg)] loads: Vec<(Bound<'py, PyAny>, Bound<'py, PyAny>, f64)>,
        steps: errors::Int,
        #[pyo3(from_py_with = conv::arg)] dt: f64,
        #[pyo3(from_py_with = conv::arg)] ramp_start: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] stable_limit: f64,
        #[pyo3(from_py_with = conv::arg)] max_wall_s: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let this = &mut *slf;
        let n = this.model.n_nodes();
        let start = ramp_start.unwrap_or(this.state.t);
        let loads = loads
            .iter()
            .enumerate()
            .map(|(k, (nodes, force, ramp))| py_load(n, conv::node_indices(nodes, &format!("loads[{k}] nodes"), n)?, force, *ramp, start))
            .collect::<PyResult<Vec<_>>>()?;
        let steps = errors::count(steps, "steps")?;
        for (k, l) in loads.iter().enumerate() {
            let share = l.total_force().norm() / l.nodes().len().max(1) as f64;
            errors::warn_fixed_load(py, this.model.fixed(), l.nodes().iter().map(|&i| (i, share)), &format!("run_loads: loads[{k}]"))?;
        }
        this.run_timed(py, &loads, steps, dt, stable_limit, max_wall_s)
    }

    /// The state with the integrator's memory, as a dict of copies: ``positions`` [m],
    /// ``velocities`` [m/s] and ``forces`` [N], each (n, 3) float64, world frame; ``time`` [s];
    /// ``factored_dt`` [s] (the dt the factor in use was made for, NaN if none),
    /// ``refreshed_at`` [m] ((n, 3) positions where the quasi-Newton / Newton factor was
    /// refreshed, or None: the rest matrix) and ``excess_iterations`` (the refresh rule's count).
    /// Plain Python and numpy values: it pickles.
    fn get_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let mem = self.ws.memory();
        d.set_item("positions", conv::vec3s_to_py(py, &self.state.x))?;
        d.set_item("velocities", conv::vec3s_to_py(py, &self.state.v))?;
        d.set_item("forces", conv::vec3s_to_py(py, &self.state.f_ext))?;
        d.set_item("time", self.state.t)?;
        d.set_item("factored_dt", mem.factored_dt)?;
        d.set_item("refreshed_at", mem.refreshed_at.as_ref().map(|x| conv::vec3s_to_py(py, x)))?;
        d.set_item("excess_iterations", mem.excess_iterations)?;
        Ok(d)
    }

    /// Restore a state from :meth:`get_state` (of this body or one built the same way): the next
    /// steps repeat those that followed it bit for bit. Remakes the factor it records (one
    /// factorisation unless held or cached). Raises ``KeyError`` for a missing entry,
    /// ``ValueError`` for a wrong shape or a non-finite value, ``StepError`` if the factorisation
    /// fails; the body is unchanged then.
    fn set_state(&mut self, py: Python<'_>, #[pyo3(from_py_with = conv::arg)] state: Bound<'_, PyDict>) -> PyResult<()> {
        let n = self.model.n_nodes();
        let x = conv::vec3s(&item(&state, "positions")?, "positions", n, true)?;
        let v = conv::vec3s(&item(&state, "velocities")?, "velocities", n, true)?;
        let f_ext = conv::forces(&item(&state, "forces")?, "forces", n)?;
        let t: f64 = conv::arg(&item(&state, "time")?)?;
        if !t.is_finite() {
            return Err(crate::errors::param_error_from(format!("time = {t} s must be finite")));
        }
        let refreshed = item(&state, "refreshed_at")?;
        let mem = StepMemory {
            factored_dt: conv::arg(&item(&state, "factored_dt")?)?,
            refreshed_at: if refreshed.is_none() { None } else { Some(conv::vec3s(&refreshed, "refreshed_at", n, true)?) },
            excess_iterations: conv::arg(&item(&state, "excess_iterations")?)?,
            // A body is stepped with no potential of the caller's: its factor holds no terms.
            base_terms: Vec::new(),
            term_updates: Vec::new(),
        };
        let (model, ws) = (&self.model, &mut self.ws);
        errors::guard("Body.set_state", || py.detach(|| ws.restore_memory(model, &mem)).map_err(|e| errors::step_error(e, "in set_state")))?;
        self.state = State { x, v, t, f_ext };
        Ok(())
    }

    /// Set the positions of every node [m], (n, 3), world frame (e.g. an initial deformation);
    /// fixed nodes stay where they are put. Velocities, forces and time are kept.
    fn set_positions(&mut self, positions: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.x = conv::vec3s(positions, "positions", self.model.n_nodes(), true)?;
        Ok(())
    }

    /// Set the velocities of every node [m/s], (n, 3), world frame (fixed nodes: zeroed by the
    /// next step).
    fn set_velocities(&mut self, velocities: &Bound<'_, PyAny>) -> PyResult<()> {
        self.state.v = conv::vec3s(velocities, "velocities", self.model.n_nodes(), true)?;
        Ok(())
    }

    /// Factorise the implicit integrators' matrix for ``dt`` [s] ahead of the first step at that
    /// ``dt`` (GIL released), so that a haptic loop does not stall on it: besides the factor in
    /// use, the rest factors of the 3 ``dt`` used or prepared most recently are kept (each the
    /// memory of one factor), and returning to one costs no factorisation. Changes the cost of later steps, never their
    /// result. Returns whether it factorised (False: already held, or the semi-implicit scheme,
    /// which has no factor). Raises ``StepError`` for a bad ``dt`` or a failed factorisation.
    fn prepare(&mut self, py: Python<'_>, #[pyo3(from_py_with = conv::arg)] dt: f64) -> PyResult<bool> {
        let (model, ws) = (&self.model, &mut self.ws);
        errors::guard("Body.prepare", || py.detach(|| ws.prepare(model, dt)).map_err(|e| errors::step_error(e, "in prepare")))
    }

    /// An independent copy: the same model (shared mesh and material objects, which are
    /// immutable), state, integrator memory and cached factors.
    fn copy(&self, py: Python<'_>) -> PyBody {
        PyBody {
            model: self.model.clone(),
            state: self.state.clone(),
            ws: self.ws.clone(),
            mesh: self.mesh.clone_ref(py),
            material: self.material.clone_ref(py),
        }
    }

    fn __copy__(&self, py: Python<'_>) -> PyBody {
        self.copy(py)
    }

    fn __deepcopy__(&self, py: Python<'_>, _memo: &Bound<'_, PyAny>) -> PyBody {
        self.copy(py)
    }

    fn __repr__(&self) -> String {
        let m = self.material.get().inner;
        format!(
            "<palpate.Body: {} nodes, {} tets, {} fixed; E = {} Pa, nu = {}, {} kg/m^3; {}; t = {} s>",
            self.model.n_nodes(),
            self.model.n_tets(),
            self.model.fixed().iter().filter(|&&f| f).count(),
            sig4(m.young()),
            sig4(m.poisson()),
            sig4(m.density()),
            integrator_words(self.model.integrator()),
            self.state.t
        )
    }
}
