//! `palpate._palpate`: the Python extension module, a thin layer over `palpate-core`.
//!
//! | file | binds |
//! |---|---|
//! | `errors.rs` | core error enums -> `palpate.PalpateError` and its subclasses (the whole tree: `MeshError`, `SurfaceError`, `MaterialError`, `ModelError`, `ModelFileError`, `SolveError`, `StepError`, `MeshWarning`) |
//! | `conv.rs` | numpy <-> core arrays (dtype / shape checks) |
//! | `mesh.rs` | `TetMesh`, `ellipsoid_wall`, `truncated_ellipsoid_wall`, `box_mesh` |
//! | `material.rs` | `Law`, `Material` |
//! | `integrator.rs` | `SemiImplicit`, `BackwardEuler`, `Filter`, `Solver` |
//! | `body.rs` | `Body` (model + state + workspace; stepping releases the GIL) |
//! | `particles.rs` | `Kernel`, `ParticleBody`, `TriSurface`, `ellipsoid_surface`, `sample_inside`, `sample_between` |
//!
//! The Pythonic layer (file IO, CLI, benchmark) lives in `python/palpate/*.py`.

mod body;
mod conv;
mod errors;
mod hybrid;
mod integrator;
mod material;
mod mesh;
mod particles;

use pyo3::prelude::*;

#[pymodule]
fn _palpate(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    m.add_class::<mesh::PyTetMesh>()?;
    m.add_class::<material::PyLaw>()?;
    m.add_class::<material::PyMaterial>()?;
    m.add_class::<integrator::PySemiImplicit>()?;
    m.add_class::<integrator::PyBackwardEuler>()?;
    m.add_class::<integrator::PyFilter>()?;
    m.add_class::<integrator::PySolver>()?;
    m.add_class::<body::PyBody>()?;
    m.add_function(wrap_pyfunction!(mesh::ellipsoid_wall, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::truncated_ellipsoid_wall, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::box_mesh, m)?)?;
    particles::register(m)?;
    hybrid::register(m)?;
    Ok(())
}
