//! `palpate.HybridSim`: the hybrid model you can touch (`palpate_core::runtime`), tool position
//! in, force out. Ticks release the GIL.

use numpy::{PyArray1, PyArray2};
use palpate_core::integrate::StiffnessTerm;
use palpate_core::parallel::Serial;
use palpate_core::runtime::{
    finish_tick, scale, tick, tick_force_with, Sim, SimOptions, SimSnapshot, SimState, SimWorkspace, SkinSweep, TickReport, ToolOptions,
};
use palpate_core::{StepMemory, Vec3};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::body::sig4;

use crate::conv;
use crate::errors;
use crate::hybrid::PyHybridModel;
use crate::material::PyMaterial;

/// The hybrid simulation of a built model (paper §5-§7): an FEM core, the particles under the
/// tool active, the skin following both. Stays finite under a hand's worst on the shipped models
/// (15 mm presses, jumps, jabs, fast slides: tests/runtime_hand.rs, ``bench/hybrid_hand.py``);
/// not yet at its speed target (BENCHMARKS.md).
///
/// ``HybridSim(model, material, *, tool_radius=0.005, tool_area_stiffness=None,
/// core_contact_stiffness=None, hold=True, activation_margin=None, max_tool_speed=None, linger=None, max_substeps=None,
/// mass_scaling=None, shell_fallback=True, shell_pause=None, homogenise=True, implicit_exchange=True,
/// strict_units=False)``
///
/// Parameters
/// ----------
/// model : HybridModel
/// material : Material
///     Of the core and the shell (St. Venant-Kirchhoff).
/// tool_radius : float
///     The spherical tool's radius [m].
/// tool_area_stiffness : float, optional
///     Penalty stiffness per unit of skin area [N/m^3] (default ``12 E* / min(R, 4 h)``, with
///     ``h`` the model's lattice spacing: ten times the tissue's Hertz stiffness per unit area
///     under the smallest contact the model resolves; 8.6e7 for myocardium and the 5 mm tool on
///     the Rodero model); each skin vertex in contact carries a third of its triangles' areas, so
///     the contact is as stiff whatever the skin's tessellation (``palpate_core::runtime::tool``).
/// core_contact_stiffness : float, optional
///     Penalty stiffness of the tool against the core's surface [N/m] (default 2000: ten times
///     the tissue's under a 5 mm sphere), met at the surface's point nearest the tool's centre,
///     signed, inside the core's implicit step, so that a hard press cannot pass the tool through
///     the organ (``palpate_core::runtime::core_contact``).
/// hold : bool
///     Hold the core at its base (or, for a closed wall, its lower 30%).
/// activation_margin : float, optional
///     Regions within the tool's radius plus this [m] become active (default 1 mm).
/// max_tool_speed : float, optional
///     The simulated tool's top speed [m/s] (default 0.5): a device that jumps is followed over
///     several ticks (``tool_position`` says where the simulated tool is), at most
///     ``max_tool_speed * dt`` a tick whatever the tick's length.
/// linger : float, optional
///     How long a region stays active after its last contact [s] (default 0.1).
/// max_substeps : int, optional
///     Cap of the particle sub-steps a tick takes (default 64).
/// mass_scaling : float, optional
///     Selective mass scaling of the shell, a quantile in (0, 1] (default 0.95; 1.0 scales
///     nothing): the particles stiffer than that quantile of them get the mass that brings them
///     down to it, kept only if that lowers the shell's top frequency by 10%. Fewer sub-steps a
///     tick on irregular lattices (Rodero: 16 -> 9 at rest for 0.9% added mass); statics
///     unchanged. ``options`` reports what was added.
/// shell_fallback : bool
///     What a failed shell step does (the particles' step diverging: a press the shell's
///     explicit sub-steps cannot follow, e.g. beside a held base, see ``last``). True (default):
///     the tick goes on without the shell (every particle back at its tie, the tool meeting the
///     skin and the core, so the hand still feels the organ) and the shell stays off for
///     ``shell_pause`` seconds and until the tool lets go of the organ. False: ``step`` raises
///     ``StepError`` with the state as it was.
/// shell_pause : float, optional
///     How long the shell stays off at least after a failure [s] (default 0.1).
/// homogenise : bool, optional
///     Stiffen the core by the model's homogenisation factor at the material's Poisson's ratio
///     (default True; ``HybridModel.homogenisation``), so that where no particle is active the
///     core bends as the whole wall does. False: the paper's core, stiff as the tissue.
/// implicit_exchange : bool, optional
///     The springs that tie the shell to the core at the tissue's stiffness ``E h``, their
///     reactions taken inside the core's step (``palpate_core::runtime::exchange``): the force
///     proportional to E and Hertz's ``sqrt(R)`` on a thick slab (default True). False: the
///     springs capped by the explicit exchange's stability (2.9 N/m on Rodero against ``E h`` =
///     49), the force 1.7x for twice E, the slab 10-23% too soft (VALIDATION.md); a few percent
///     cheaper a tick. Kept for comparison.
/// strict_units : bool, optional
///     Values most likely in the wrong unit (a Young's modulus outside soft tissue's 100 Pa to
///     10 MPa, a tool radius over 5 cm, a tool target more than 1 m from the organ's bounding
///     box: ``palpate_core::runtime::scale``) warn with ``palpate.UnitWarning`` naming the unit
///     that fits (a far target once a simulation); True makes each a ``ParameterError`` (the
///     target's in ``step``, before the tick).
///
/// ``get_state()`` / ``set_state(s)`` save and restore everything a tick carries to the next (the
/// ticks after a restore repeat the original's bit for bit); a ``HybridSim`` pickles (its model,
/// material, options and state: ``multiprocessing``, Dask) and copies (``copy()``).
///
/// Positions in metres, forces in newtons, world frame of the model.
#[pyclass(module = "palpate", name = "HybridSim")]
pub struct PyHybridSim {
    sim: Sim,
    state: SimState,
    ws: SimWorkspace,
    last: TickReport,
    /// The tool target's unit check (the outer surface's bounding box at rest, `strict_units`).
    target_check: errors::TargetCheck,
}

#[pymethods]
impl PyHybridSim {
    #[new]
    #[pyo3(signature = (model, material, *, tool_radius = None, tool_area_stiffness = None, core_contact_stiffness = None, hold = true, activation_margin = None, max_tool_speed = None, linger = None, max_substeps = None, mass_scaling = None, shell_fallback = true, shell_pause = None, homogenise = true, implicit_exchange = true, strict_units = false))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        #[pyo3(from_py_with = conv::arg)] model: PyRef<'_, PyHybridModel>,
        #[pyo3(from_py_with = conv::arg)] material: PyRef<'_, PyMaterial>,
        #[pyo3(from_py_with = conv::arg)] tool_radius: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] tool_area_stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] core_contact_stiffness: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] hold: bool,
        #[pyo3(from_py_with = conv::arg)] activation_margin: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] max_tool_speed: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] linger: Option<f64>,
        max_substeps: Option<errors::Int>,
        #[pyo3(from_py_with = conv::arg)] mass_scaling: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] shell_fallback: bool,
        #[pyo3(from_py_with = conv::arg)] shell_pause: Option<f64>,
        #[pyo3(from_py_with = conv::arg)] homogenise: bool,
        #[pyo3(from_py_with = conv::arg)] implicit_exchange: bool,
        #[pyo3(from_py_with = conv::arg)] strict_units: bool,
    ) -> PyResult<Self> {
        // Keywords into the core's options, which check themselves (SimOptions::check).
        let max_substeps = errors::count_opt(max_substeps, "max_substeps")?;
        let defaults = SimOptions::default();
        let tool = ToolOptions {
            radius: tool_radius.unwrap_or(defaults.tool.radius),
            area_stiffness: tool_area_stiffness.or(defaults.tool.area_stiffness),
            ..defaults.tool
        };
        let options = SimOptions {
            tool,
            hold,
            homogenise,
            implicit_exchange,
            core_contact_stiffness: core_contact_stiffness.unwrap_or(defaults.core_contact_stiffness),
            activation_margin: activation_margin.unwrap_or(defaults.activation_margin),
            max_tool_speed: max_tool_speed.unwrap_or(defaults.max_tool_speed),
            linger: linger.unwrap_or(defaults.linger),
            max_substeps: max_substeps.unwrap_or(defaults.max_substeps),
            mass_scaling: mass_scaling.or(defaults.mass_scaling),
            shell_fallback: if shell_fallback { shell_pause.or(defaults.shell_fallback) } else { None },
            ..defaults
        };
        options.check().map_err(|e| errors::param_error_from(format!("HybridSim: {e}")))?;
        let (hm, mat) = (model.model.clone(), material.inner);
        for w in scale::parameter_warnings(&mat, options.tool.radius) {
            errors::unit_check(py, format!("HybridSim: {w}"), strict_units)?;
        }
        let sim = errors::guard("HybridSim", || py.detach(|| Sim::new(hm, mat, options)).map_err(errors::model_error))?;
        let state = SimState::rest(&sim);
        let ws = SimWorkspace::new(&sim);
        let target_check = errors::TargetCheck::new(scale::bounding_box(&sim.hybrid.outer_points), strict_units);
        Ok(PyHybridSim { sim, state, ws, last: TickReport::default(), target_check })
    }

    /// One tick of ``dt`` [s] with the tool's centre at ``tool_centre`` (3,) [m]; returns the
    /// force on the tool (3,) [N] (what a device renders). Raises ``ValueError`` for a
    /// malformed or non-finite position and ``StepError`` for a bad ``dt`` or a failed tick (the
    /// core and particles' motion are then left as they were; the activation keeps the tick's
    /// update).
    ///
    /// ``finish=False`` stops once the force is known and leaves the rest of the tick owed (the
    /// skin's update, and the core's step when the tool has nothing of the core within reach):
    /// a loop that renders the force sends it, then calls :meth:`finish` (as palpate's haptic
    /// servo does). The next ``step`` pays what is owed first, so the ticks are the same bit for
    /// bit either way. A state taken in between (:meth:`get_state`) carries what is owed.
    #[pyo3(signature = (tool_centre, dt = 1e-3, *, finish = true))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        tool_centre: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = conv::arg)] dt: f64,
        #[pyo3(from_py_with = conv::arg)] finish: bool,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let c = conv::vec3(tool_centre, "tool_centre")?;
        self.target_check.check(py, "HybridSim.step", &c)?;
        let (sim, state, ws) = (&self.sim, &mut self.state, &mut self.ws);
        let r = errors::guard("HybridSim.step", || {
            py.detach(|| if finish { tick(sim, state, ws, c, dt) } else { tick_force_with(sim, state, ws, c, dt, &Serial) })
                .map_err(|e| errors::step_error(e, "in the hybrid tick"))
        })?;
        self.last = r;
        Ok(conv::vec3_to_py(py, r.force))
    }

    /// The rest of a tick stepped with ``finish=False`` (nothing when nothing is owed): the
    /// core's step when it was owed, then the skin's update. Raises ``StepError`` when the owed
    /// core step fails: the core is then as it was, the particles where the tick left them, the
    /// tick counted (its force was given): go back to a state you trust (:meth:`set_state`).
    fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        let (sim, state, ws) = (&self.sim, &mut self.state, &mut self.ws);
        let done = errors::guard("HybridSim.finish", || {
            py.detach(|| finish_tick(sim, state, ws)).map_err(|e| errors::step_error(e, "in the rest of the hybrid tick"))
        })?;
        if let Some(core) = done.core {
            self.last.core = core;
        }
        self.last.skin_refreshed += done.skin_refreshed;
        Ok(())
    }

    /// The last tick's statistics: ``force`` (3,) [N], ``particle_contacts`` (skin vertices in
    /// contact over active particles), ``skin_contacts`` (those no particle carries: the core takes their force), ``core_contacts`` (1 when the tool touches the core's surface), ``max_depth_m``, ``active``, ``entered``, ``left``, ``substeps``,
    /// ``confined``, ``core_iterations``, ``shell_failed`` (the shell's step failed and was shed:
    /// see ``shell_fallback``) and ``shell_off`` (the shell was off, within its pause).
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
        d.set_item("shell_failed", r.shell_failed)?;
        d.set_item("shell_off", r.shell_off)?;
        Ok(d)
    }

    /// Outer-surface (skin) vertex positions [m], (n_outer, 3).
    #[getter]
    fn surface<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let mut out = vec![Vec3::zeros(); self.state.skin.len()];
        self.sim.skin_positions(&self.state, &mut out);
        conv::vec3s_to_py(py, &out)
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

    /// The tool's radius [m].
    #[getter]
    fn tool_radius(&self) -> f64 {
        self.sim.options.tool.radius
    }

    /// Where the simulated tool's centre is [m] (3,), or ``None`` before the first tick: it
    /// follows the device's ``tool_centre`` at most at ``max_tool_speed``.
    #[getter]
    fn tool_position<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.state.tool.map(|c| conv::vec3_to_py(py, c))
    }

    /// The options the simulation was made with: ``tool_radius`` [m], ``tool_area_stiffness``
    /// [N/m^3] and ``tool_area_damping`` [N s/m^3] (resolved: per unit of skin area),
    /// ``core_contact_stiffness`` [N/m] (the tool against the core's
    /// surface), ``activation_margin`` [m], ``max_tool_speed`` [m/s],
    /// ``linger`` [s], ``max_substeps``, ``hold``, ``implicit_exchange``, ``strict_units``, ``mass_scaling`` (the quantile), the resolved
    /// ``coupling_stiffness`` [N/m], ``coupling_damping`` [N s/m] and ``confinement_stiffness``
    /// [N/m], and what the mass scaling did: ``mass_scaling_applied``, ``added_mass_fraction``
    /// (of the shell's mass), ``scaled_particles``, ``omega_max`` [rad/s] of the shell at rest.
    #[getter]
    fn options<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let o = &self.sim.options;
        let d = PyDict::new(py);
        d.set_item("tool_radius", o.tool.radius)?;
        d.set_item("tool_area_stiffness", self.sim.tool.stiffness)?;
        d.set_item("tool_area_damping", self.sim.tool.damping)?;
        d.set_item("core_contact_stiffness", o.core_contact_stiffness)?;
        d.set_item("activation_margin", o.activation_margin)?;
        d.set_item("max_tool_speed", o.max_tool_speed)?;
        d.set_item("linger", o.linger)?;
        d.set_item("max_substeps", o.max_substeps)?;
        d.set_item("hold", o.hold)?;
        d.set_item("strict_units", self.target_check.strict)?;
        d.set_item("homogenise", o.homogenise)?;
        d.set_item("implicit_exchange", o.implicit_exchange)?;
        d.set_item("core_stiffening", self.sim.core_stiffening())?;
        d.set_item("core_active_stiffening", self.sim.active_core_stiffening())?;
        d.set_item("shell_fallback", o.shell_fallback.is_some())?;
        d.set_item("shell_pause", o.shell_fallback)?;
        d.set_item("coupling_stiffness", self.sim.coupling.stiffness)?;
        d.set_item("coupling_damping", self.sim.coupling.damping)?;
        d.set_item("confinement_stiffness", self.sim.confinement.stiffness)?;
        let ms = self.sim.particles.mass_scaling();
        d.set_item("mass_scaling", o.mass_scaling)?;
        d.set_item("mass_scaling_applied", ms.applied)?;
        d.set_item("added_mass_fraction", if ms.applied { ms.added_fraction } else { 0.0 })?;
        d.set_item("scaled_particles", if ms.applied { ms.scaled } else { 0 })?;
        d.set_item("omega_max", self.sim.particles.omega_max())?;
        Ok(d)
    }

    /// The model it simulates (a copy: a ``HybridModel`` is immutable).
    #[getter]
    fn model(&self) -> PyHybridModel {
        PyHybridModel { model: self.sim.hybrid.clone() }
    }

    /// The material of the core and the shell.
    #[getter]
    fn material(&self) -> PyMaterial {
        PyMaterial { inner: *self.sim.material() }
    }

    /// The state as a dict of copies, everything a tick carries to the next: ``time`` [s],
    /// ``ticks``; ``core_positions`` [m] and ``core_velocities`` [m/s] (n_core, 3) with the core
    /// integrator's memory (``factored_dt`` [s], ``refreshed_at`` [m] or None,
    /// ``excess_iterations``: as ``Body.get_state``; ``factor_base_terms`` and
    /// ``factor_term_updates`` (k, 8): the shell's coupling springs the factor holds, as held when
    /// it was made and the rank updates since, rows ``[id, node0, node1, node2, w0, w1, w2,
    /// stiffness]``, the stiffness [N/m] negative for a spring removed); ``particle_positions`` [m] and
    /// ``particle_velocities`` [m/s] (n_particles, 3) (the inactive ones where the last tick left
    /// them); ``tool`` [m] (3,) or None; the activation's hysteresis, ``region_last_touched``
    /// (per region the tick of its last contact, -1: never) and ``active_regions`` (in the
    /// runtime's order); ``skin`` [m] (n_outer, 3) as stored (fresh near the tool, within 5 mm
    /// elsewhere); and the bookkeeping of the work a tick skips, which changes no force (kept so
    /// that a restored simulation also does the same work): ``skin_live`` (the vertices a tick
    /// looks at, None before the first whole update), ``skin_carried`` (those placed by
    /// particles), ``skin_reference`` [m] (core positions at the last whole update),
    /// ``skin_reference_tool`` [m], ``skin_slack`` [m], and the sweep of the whole skin in
    /// progress: ``skin_sweep_next`` (its next vertex, None without a sweep),
    /// ``skin_sweep_reference`` [m] (n_core, 3) or None, ``skin_sweep_slack`` [m], and
    /// ``shell_off_until`` (the tick the shell may return at after a failure, 0: on), and the
    /// skin a shed shell left lifted off its ties, fading back: ``skin_lift_vertices`` (k,),
    /// ``skin_lift_offsets`` [m] (k, 3), ``skin_lift_start`` (the shed tick); what a tick stepped
    /// with ``finish=False`` still owes: ``owed_skin`` (bool), ``owed_core_dt`` [s] (None: the
    /// core's step is not owed) and ``owed_core_forces`` [N] (n_core, 3) or None (the forces it
    /// steps under); ``dt`` [s], the last tick's length (the time-valued options count ticks of
    /// it; absent from older states: 1 ms). Positions world frame. Plain Python and numpy values:
    /// it pickles.
    fn get_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.state.snapshot(&self.ws);
        let d = PyDict::new(py);
        d.set_item("time", s.time)?;
        d.set_item("ticks", s.ticks)?;
        d.set_item("core_positions", conv::vec3s_to_py(py, &s.core_x))?;
        d.set_item("core_velocities", conv::vec3s_to_py(py, &s.core_v))?;
        d.set_item("factored_dt", s.core_memory.factored_dt)?;
        d.set_item("refreshed_at", s.core_memory.refreshed_at.as_ref().map(|x| conv::vec3s_to_py(py, x)))?;
        d.set_item("excess_iterations", s.core_memory.excess_iterations)?;
        let row = |t: &StiffnessTerm, sign: f64| {
            [
                t.id as f64,
                t.nodes[0] as f64,
                t.nodes[1] as f64,
                t.nodes[2] as f64,
                t.weights[0],
                t.weights[1],
                t.weights[2],
                sign * t.stiffness,
            ]
        };
        let base: Vec<[f64; 8]> = s.core_memory.base_terms.iter().map(|t| row(t, 1.0)).collect();
        let updates: Vec<[f64; 8]> = s.core_memory.term_updates.iter().map(|(t, added)| row(t, if *added { 1.0 } else { -1.0 })).collect();
        d.set_item("factor_base_terms", conv::f64_rows_to_py(py, &base))?;
        d.set_item("factor_term_updates", conv::f64_rows_to_py(py, &updates))?;
        d.set_item("particle_positions", conv::vec3s_to_py(py, &s.particle_x))?;
        d.set_item("particle_velocities", conv::vec3s_to_py(py, &s.particle_v))?;
        d.set_item("tool", s.tool.map(|c| conv::vec3_to_py(py, c)))?;
        let last: Vec<i64> = s.last_touched.iter().map(|&t| i64::try_from(t).unwrap_or(-1)).collect();
        d.set_item("region_last_touched", PyArray1::from_vec(py, last))?;
        d.set_item("active_regions", conv::u32s_to_py(py, &s.regions))?;
        d.set_item("skin", conv::vec3s_to_py(py, &s.skin))?;
        d.set_item("skin_live", s.live.as_ref().map(|l| conv::u32s_to_py(py, l)))?;
        d.set_item("skin_carried", conv::flagged_to_py(py, &s.carried))?;
        d.set_item("skin_reference", conv::vec3s_to_py(py, &s.live_ref_x))?;
        d.set_item("skin_reference_tool", conv::vec3_to_py(py, s.live_ref_tool))?;
        d.set_item("skin_slack", s.live_slack)?;
        d.set_item("skin_sweep_next", s.sweep.as_ref().map(|w| w.next))?;
        d.set_item("skin_sweep_reference", s.sweep.as_ref().map(|w| conv::vec3s_to_py(py, &w.ref_x)))?;
        d.set_item("skin_sweep_slack", s.sweep.as_ref().map_or(0.0, |w| w.slack))?;
        d.set_item("shell_off_until", s.shell_off_until)?;
        let (lv, lo): (Vec<u32>, Vec<_>) = s.skin_lift.iter().copied().unzip();
        d.set_item("skin_lift_vertices", conv::u32s_to_py(py, &lv))?;
        d.set_item("skin_lift_offsets", conv::vec3s_to_py(py, &lo))?;
        d.set_item("skin_lift_start", s.skin_lift_start)?;
        d.set_item("owed_skin", s.skin_owed)?;
        d.set_item("owed_core_dt", s.core_owed.as_ref().map(|(dt, _)| *dt))?;
        d.set_item("owed_core_forces", s.core_owed.as_ref().map(|(_, f)| conv::vec3s_to_py(py, f)))?;
        d.set_item("dt", s.dt)?;
        Ok(d)
    }

    /// Restore a state from :meth:`get_state` (of this simulation, a copy, or one made from the
    /// same model, material and options: an unpickled one): the next ticks repeat those that
    /// followed it bit for bit. Remakes the core's factor (one factorisation); the last tick's
    /// report (``last``) is cleared. Raises ``KeyError`` for a missing entry, ``ValueError`` for
    /// a wrong shape, index or non-finite value, ``StepError`` for a state that does not fit
    /// this simulation or a failed factorisation; the simulation is unchanged then.
    fn set_state(&mut self, py: Python<'_>, #[pyo3(from_py_with = conv::arg)] state: Bound<'_, PyDict>) -> PyResult<()> {
        let item = |key: &str| state.get_item(key)?.ok_or_else(|| crate::errors::key_error(format!("state has no {key:?} (a dict from get_state())")));
        let (n_core, n_p, n_skin) = (self.sim.core.n_nodes(), self.sim.n_particles(), self.sim.hybrid.outer_points.len());
        let skin_items = conv::Items { item: "point", owner: "the skin" };
        let opt = |key: &str| -> PyResult<Option<Bound<'_, PyAny>>> { item(key).map(|v| (!v.is_none()).then_some(v)) };
        let unsigned = |key: &str, never: bool| -> PyResult<Vec<i64>> {
            let v = conv::codes(&item(key)?, key, "a 1-D integer array")?;
            match v.iter().find(|&&t| t < if never { -1 } else { 0 }) {
                Some(t) => Err(errors::param_error_from(format!("{key}: {t} is negative"))),
                None => Ok(v),
            }
        };
        let mut carried = vec![false; n_skin];
        for v in conv::indices(&item("skin_carried")?, "skin_carried", n_skin, skin_items, true)? {
            carried[v] = true;
        }
        let snap = SimSnapshot {
            time: conv::arg(&item("time")?)?,
            ticks: conv::arg(&item("ticks")?)?,
            core_x: conv::vec3s(&item("core_positions")?, "core_positions", n_core, true)?,
            core_v: conv::vec3s(&item("core_velocities")?, "core_velocities", n_core, true)?,
            core_memory: StepMemory {
                factored_dt: conv::arg(&item("factored_dt")?)?,
                refreshed_at: opt("refreshed_at")?.map(|x| conv::vec3s(&x, "refreshed_at", n_core, true)).transpose()?,
                excess_iterations: conv::arg(&item("excess_iterations")?)?,
                base_terms: terms(opt("factor_base_terms")?, "factor_base_terms", n_core)?.into_iter().map(|(t, _)| t).collect(),
                term_updates: terms(opt("factor_term_updates")?, "factor_term_updates", n_core)?,
            },
            particle_x: conv::vec3s(&item("particle_positions")?, "particle_positions", n_p, true)?,
            particle_v: conv::vec3s(&item("particle_velocities")?, "particle_velocities", n_p, true)?,
            skin: conv::vec3s(&item("skin")?, "skin", n_skin, true)?,
            tool: opt("tool")?.map(|c| conv::vec3(&c, "tool")).transpose()?,
            last_touched: unsigned("region_last_touched", true)?.iter().map(|&t| u64::try_from(t).unwrap_or(u64::MAX)).collect(),
            regions: unsigned("active_regions", false)?.iter().map(|&s| u32::try_from(s).unwrap_or(u32::MAX)).collect(),
            live: opt("skin_live")?
                .map(|l| conv::indices(&l, "skin_live", n_skin, skin_items, true))
                .transpose()?
                .map(|l| l.iter().map(|&v| v as u32).collect()),
            carried,
            live_ref_x: conv::vec3s(&item("skin_reference")?, "skin_reference", n_core, true)?,
            live_ref_tool: conv::vec3(&item("skin_reference_tool")?, "skin_reference_tool")?,
            live_slack: conv::arg(&item("skin_slack")?)?,
            sweep: match opt("skin_sweep_next")? {
                None => None,
                Some(next) => {
                    let next: i64 = conv::arg(&next)?;
                    let reference =
                        opt("skin_sweep_reference")?.ok_or_else(|| errors::param_error_from("skin_sweep_reference: None beside a skin_sweep_next"))?;
                    Some(SkinSweep {
                        next: usize::try_from(next).map_err(|_| errors::param_error_from(format!("skin_sweep_next = {next}: must not be negative")))?,
                        ref_x: conv::vec3s(&reference, "skin_sweep_reference", n_core, true)?,
                        slack: conv::arg(&item("skin_sweep_slack")?)?,
                    })
                }
            },
            // Absent from states saved before the shell fallback: the shell on.
            shell_off_until: match opt("shell_off_until")? {
                None => 0,
                Some(t) => {
                    let t: i64 = conv::arg(&t)?;
                    u64::try_from(t).map_err(|_| errors::param_error_from(format!("shell_off_until = {t}: must not be negative")))?
                }
            },
            skin_lift: Vec::new(),
            skin_lift_start: 0,
            // What a tick stepped with `finish=False` still owes (absent from older states:
            // nothing).
            skin_owed: match opt("owed_skin")? {
                None => false,
                Some(b) => conv::arg(&b)?,
            },
            core_owed: match opt("owed_core_dt")? {
                None => None,
                Some(dt) => {
                    let forces = opt("owed_core_forces")?.ok_or_else(|| errors::param_error_from("owed_core_forces: None beside an owed_core_dt"))?;
                    Some((conv::arg(&dt)?, conv::vec3s(&forces, "owed_core_forces", n_core, true)?))
                }
            },
            // The last tick's length (absent from older states: the 1 ms tick).
            dt: match state.get_item("dt")?.filter(|v| !v.is_none()) {
                None => palpate_core::runtime::sim::TICK,
                Some(dt) => conv::arg(&dt)?,
            },
        };
        // The skin's lift after a shed shell (absent from older states: none).
        let mut snap = snap;
        if let Some(vertices) = state.get_item("skin_lift_vertices")?.filter(|v| !v.is_none()) {
            let vertices = conv::indices(&vertices, "skin_lift_vertices", n_skin, skin_items, true)?;
            let offsets = conv::vec3s(&item("skin_lift_offsets")?, "skin_lift_offsets", vertices.len(), true)?;
            snap.skin_lift = vertices.iter().map(|&v| v as u32).zip(offsets).collect();
            let t: i64 = conv::arg(&item("skin_lift_start")?)?;
            snap.skin_lift_start = u64::try_from(t).map_err(|_| errors::param_error_from(format!("skin_lift_start = {t}: must not be negative")))?;
        }
        let sim = &self.sim;
        let (state, ws) = py.detach(|| SimState::restore(sim, &snap)).map_err(|e| errors::step_error(e, "in set_state"))?;
        (self.state, self.ws, self.last) = (state, ws, TickReport::default());
        Ok(())
    }

    /// Back to rest: the core and the shell undeformed, nothing active, time and ticks zero, no
    /// tool (the compiled model is kept: cheaper than a new ``HybridSim``).
    fn reset(&mut self) {
        self.state = SimState::rest(&self.sim);
        self.ws = SimWorkspace::new(&self.sim);
        self.last = TickReport::default();
    }

    /// An independent copy (model, state, workspace and last tick report): a snapshot to go
    /// back to (``sim = snapshot.copy()``) or to try a different touch from. Ticks of the copy
    /// repeat those of the original bit for bit.
    fn copy(&self) -> PyHybridSim {
        PyHybridSim {
            sim: self.sim.clone(),
            state: self.state.clone(),
            ws: self.ws.clone(),
            last: self.last,
            target_check: self.target_check.clone(),
        }
    }

    fn __copy__(&self) -> PyHybridSim {
        self.copy()
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> PyHybridSim {
        self.copy()
    }

    fn __repr__(&self) -> String {
        let m = self.sim.material();
        format!(
            "<palpate.HybridSim: {} core tets, {} particles ({} active), {} regions; E = {} Pa, nu = {}, {} kg/m^3; tool radius {} m; t = {} s, {} ticks>",
            self.sim.core.n_tets(),
            self.sim.n_particles(),
            self.state.particles.active.len(),
            self.sim.hybrid.n_regions(),
            sig4(m.young()),
            sig4(m.poisson()),
            sig4(m.density()),
            sig4(self.sim.options.tool.radius),
            self.state.time(),
            self.state.ticks
        )
    }
}

/// The stiffness terms of a state's ``factor_base_terms`` or ``factor_term_updates`` (k, 8): rows
/// ``[id, node0, node1, node2, w0, w1, w2, stiffness]``, the stiffness [N/m] signed (negative: a
/// term removed); absent from states saved before they were kept: none.
fn terms(rows: Option<Bound<'_, PyAny>>, what: &str, n_core: usize) -> PyResult<Vec<(StiffnessTerm, bool)>> {
    let Some(rows) = rows else { return Ok(Vec::new()) };
    let (v, shape) = conv::reals_nd(&rows, what)?;
    if v.is_empty() {
        return Ok(Vec::new());
    }
    if shape.len() != 2 || shape[1] != 8 {
        return Err(errors::param_error_from(format!("{what} must have shape (k, 8), got {shape:?}")));
    }
    let index = |x: f64, limit: usize| (x >= 0.0 && x.fract() == 0.0 && x < limit as f64).then_some(x as usize);
    v.chunks_exact(8)
        .enumerate()
        .map(|(j, r)| {
            let bad = |why: &str| errors::param_error_from(format!("{what}[{j}] = {r:?}: {why}"));
            let id = index(r[0], u32::MAX as usize).ok_or_else(|| bad("the id must be a non-negative integer"))? as u32;
            let mut nodes = [0usize; 3];
            for (k, n) in nodes.iter_mut().enumerate() {
                *n = index(r[1 + k], n_core).ok_or_else(|| bad(&format!("nodes must be integers below {n_core}")))?;
            }
            let (weights, k) = ([r[4], r[5], r[6]], r[7]);
            if !(weights.iter().all(|w| w.is_finite()) && k.is_finite() && k != 0.0) {
                return Err(bad("weights and a non-zero stiffness must be finite"));
            }
            Ok((StiffnessTerm { id, nodes, weights, stiffness: k.abs() }, k > 0.0))
        })
        .collect()
}
