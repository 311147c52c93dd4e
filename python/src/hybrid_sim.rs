//! `palpate.HybridSim`: the hybrid model you can touch (`palpate_core::runtime`), tool position
//! in, force out. Ticks release the GIL.

use numpy::{PyArray1, PyArray2};
use palpate_core::runtime::{tick, Sim, SimOptions, SimState, SimWorkspace, TickReport, Tool};
use palpate_core::Vec3;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::conv;
use crate::errors;
use crate::hybrid::PyHybridModel;
use crate::material::PyMaterial;

/// The hybrid simulation of a built model (paper §5-§7): an FEM core, the particles under the
/// tool active, the skin following both. **In progress** (issue 12): stable for presses up to
/// 15 mm on the synthetic ventricle; see ``palpate_core::runtime`` for what is not yet.
///
/// ``HybridSim(model, material, *, tool_radius=0.005, tool_stiffness=None, hold=True)``
///
/// Parameters
/// ----------
/// model : HybridModel
/// material : Material
///     Of the core and the shell (St. Venant-Kirchhoff).
/// tool_radius : float
///     The spherical tool's radius [m].
/// tool_stiffness : float, optional
///     Penalty stiffness per skin vertex in contact [N/m] (default: the core's, see
///     ``palpate_core::runtime::tool``).
/// hold : bool
///     Hold the core at its base (or, for a closed wall, its lower 30%).
///
/// Positions in metres, forces in newtons, world frame of the model.
#[pyclass(module = "palpate", name = "HybridSim")]
pub struct PyHybridSim {
    sim: Sim,
    state: SimState,
    ws: SimWorkspace,
    last: TickReport,
}

#[pymethods]
impl PyHybridSim {
    #[new]
    #[pyo3(signature = (model, material, *, tool_radius = None, tool_stiffness = None, hold = true))]
    fn new(py: Python<'_>, model: &PyHybridModel, material: &PyMaterial, tool_radius: Option<f64>, tool_stiffness: Option<f64>, hold: bool) -> PyResult<Self> {
        let mut tool = Tool::default();
        if let Some(r) = tool_radius {
            if !(r > 0.0 && r.is_finite()) {
                return Err(PyValueError::new_err(format!("tool_radius = {r} m must be positive and finite")));
            }
            tool.radius = r;
        }
        if let Some(k) = tool_stiffness {
            if !(k > 0.0 && k.is_finite()) {
                return Err(PyValueError::new_err(format!("tool_stiffness = {k} N/m must be positive and finite")));
            }
            tool.stiffness = k;
        }
        let options = SimOptions { tool, hold, ..Default::default() };
        let (hm, mat) = (model.model.clone(), material.inner);
        let sim = py.detach(|| Sim::new(hm, mat, options)).map_err(errors::model_error)?;
        let state = SimState::rest(&sim);
        let ws = SimWorkspace::new(&sim);
        Ok(PyHybridSim { sim, state, ws, last: TickReport::default() })
    }

    /// One tick of ``dt`` [s] with the tool's centre at ``tool_centre`` (3,) [m]; returns the
    /// force on the tool (3,) [N] (what a device renders). Raises ``ValueError`` for a
    /// malformed or non-finite position and ``StepError`` for a bad ``dt`` or a failed tick (the
    /// core and particles' motion are then left as they were; the activation keeps the tick's
    /// update).
    #[pyo3(signature = (tool_centre, dt = 1e-3))]
    fn step<'py>(&mut self, py: Python<'py>, tool_centre: &Bound<'py, PyAny>, dt: f64) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let c = conv::vec3(tool_centre, "tool_centre")?;
        let (sim, state, ws) = (&self.sim, &mut self.state, &mut self.ws);
        let r = py.detach(|| tick(sim, state, ws, c, dt)).map_err(|e| errors::step_error(e, "in the hybrid tick"))?;
        self.last = r;
        Ok(conv::vec3_to_py(py, r.force))
    }

    /// The last tick's statistics: ``force`` (3,) [N], ``particle_contacts`` (skin vertices in
    /// contact over active particles), ``skin_contacts`` (over the core alone), ``core_contacts``, ``max_depth_m``, ``active``, ``entered``, ``left``, ``substeps``,
    /// ``confined``, ``core_iterations``.
    #[getter]
    fn last<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.last;
        let d = PyDict::new(py);
        d.set_item("force", conv::vec3_to_py(py, r.force))?;
        d.set_item("particle_contacts", r.particle_contacts)?;
        d.set_item("skin_contacts", r.skin_contacts)?;
        d.set_item("core_contacts", r.core_contacts)?;
        d.set_item("max_depth_m", r.max_depth)?;
        d.set_item("active", r.active)?;
        d.set_item("entered", r.entered)?;
        d.set_item("left", r.left)?;
        d.set_item("substeps", r.substeps)?;
        d.set_item("confined", r.confined)?;
        d.set_item("core_iterations", r.core.iterations)?;
        Ok(d)
    }

    /// Outer-surface (skin) vertex positions [m], (n_outer, 3).
    #[getter]
    fn surface<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.skin)
    }

    /// Outer-surface triangles, (m, 3) int64.
    #[getter]
    fn surface_triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.sim.hybrid.outer_tris)
    }

    /// Core node positions [m], (n_core, 3).
    #[getter]
    fn core_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.state.core.x)
    }

    /// Core tetrahedra, (t, 4) int64.
    #[getter]
    fn core_tets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.sim.hybrid.core_tets)
    }

    /// Indices of the active particles, (k,) int64.
    #[getter]
    fn active<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::usizes_to_py(py, &self.state.particles.active)
    }

    /// Every particle's position [m], (n_particles, 3): the active ones as simulated, the others
    /// where their ties to the core put them.
    fn particle_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let mut out = vec![Vec3::zeros(); self.sim.n_particles()];
        self.sim.particle_positions(&self.state, &mut out);
        conv::vec3s_to_py(py, &out)
    }

    /// Simulated time [s].
    #[getter]
    fn time(&self) -> f64 {
        self.state.time()
    }

    /// Ticks taken.
    #[getter]
    fn ticks(&self) -> u64 {
        self.state.ticks
    }

    /// Number of shell particles.
    #[getter]
    fn n_particles(&self) -> usize {
        self.sim.n_particles()
    }

    fn __repr__(&self) -> String {
        format!(
            "HybridSim(core_tets={}, particles={}, regions={}, tool_radius={} m, time={} s)",
            self.sim.core.n_tets(),
            self.sim.n_particles(),
            self.sim.hybrid.n_regions(),
            self.sim.options.tool.radius,
            self.state.time()
        )
    }
}
