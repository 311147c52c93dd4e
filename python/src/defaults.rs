//! The defaults of the builders and solvers, read from the core where they are defined
//! (`HybridOptions::default()`, `Integrator::*` constants, `StaticOptions::default()`, the
//! particle builder's constants), for `palpate.defaults` (python/palpate/defaults.py), the CLI
//! and the docs: Rust, Python, the CLI and the stubs cannot disagree.

use palpate_core::hybrid::build::{AUTO_CORE_TRIANGLES_BASE, AUTO_CORE_TRIANGLES_CLOSED};
use palpate_core::integrate::StaticOptions;
use palpate_core::meshfree::{Kernel, DEFAULT_HOURGLASS, DEFAULT_MIN_WEIGHT};
use palpate_core::Integrator;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::hybrid;
use crate::meshfree::PyKernel;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_defaults, m)?)
}

/// ``{"hybrid": ..., "quasi_newton": ..., "newton": ..., "static_solve": ..., "particles": ...}``:
/// one dict of default values per builder / solver, keyed as its keyword arguments (private:
/// read them as ``palpate.defaults``).
#[pyfunction]
fn _defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    let h = hybrid::default_options(py)?;
    h.set_item("auto_core_triangles_closed", AUTO_CORE_TRIANGLES_CLOSED)?;
    h.set_item("auto_core_triangles_base", AUTO_CORE_TRIANGLES_BASE)?;
    d.set_item("hybrid", h)?;

    let q = PyDict::new(py);
    q.set_item("max_iterations", Integrator::QUASI_NEWTON_MAX_ITERATIONS)?;
    q.set_item("tolerance", Integrator::QUASI_NEWTON_TOLERANCE)?;
    q.set_item("history", Integrator::QUASI_NEWTON_HISTORY)?;
    d.set_item("quasi_newton", q)?;

    let n = PyDict::new(py);
    n.set_item("max_iterations", Integrator::NEWTON_MAX_ITERATIONS)?;
    n.set_item("tolerance", Integrator::NEWTON_TOLERANCE)?;
    d.set_item("newton", n)?;

    let s = StaticOptions::default();
    let st = PyDict::new(py);
    st.set_item("max_iterations", s.max_iterations)?;
    st.set_item("tolerance", s.tolerance)?;
    st.set_item("load_steps", s.load_steps)?;
    d.set_item("static_solve", st)?;

    let p = PyDict::new(py);
    p.set_item("kernel", PyKernel::from(Kernel::default()))?;
    p.set_item("hourglass", DEFAULT_HOURGLASS)?;
    p.set_item("min_relative_weight", DEFAULT_MIN_WEIGHT)?;
    d.set_item("particles", p)?;
    Ok(d)
}
