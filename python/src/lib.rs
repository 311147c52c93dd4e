//! `palpate._palpate`: the Python extension module, a thin layer over `palpate-core`.
//!
//! | file | binds |
//! |---|---|
//! | `errors.rs` | core error enums -> `palpate.PalpateError` and its subclasses (the whole tree: `MeshError`, `SurfaceError`, `MaterialError`, `ModelError`, `ModelFileError`, `SolveError`, `StepError`, `MeshWarning`), and the warnings |
//! | `conv.rs` | numpy <-> core arrays (dtype / shape checks) and every other argument pyo3 converts (`conv::arg`: a wrong type is a `ParameterTypeError`): the one conversion layer, used by every file |
//! | `defaults.rs` | the core's defaults (hybrid builder, backward Euler, static solve, particle body) for `palpate.defaults` |
//! | `mesh.rs` | `TetMesh`, `ellipsoid_wall`, `truncated_ellipsoid_wall`, `box_mesh` (`palpate_core::mesh`) |
//! | `surface.rs` | `TriSurface`, `ellipsoid_surface`, `sample_inside`, `sample_between` (`palpate_core::mesh::{surface, sample}`) |
//! | `material.rs` | `Law`, `Material` (`palpate_core::material`) |
//! | `integrator.rs` | `SemiImplicit`, `BackwardEuler`, `Filter`, `Solver` (`palpate_core::integrate`) |
//! | `body.rs` | `Body`: the FEM body (model + state + workspace; stepping, `run_probe` and `run_loads` (`palpate_core::probe`) release the GIL) |
//! | `meshfree.rs` | `Kernel`, `kernel_value`, `neighbours`, `simd_path`, `set_simd_enabled` (`palpate_core::meshfree::{kernel, neighbors}`) |
//! | `particles.rs` | `ParticleBody`: the meshfree body (`palpate_core::meshfree`) |
//! | `hybrid.rs` | `HybridModel`, `Projection`, `ventricle_surface` (`palpate_core::hybrid`) |
//! | `hybrid_sim.rs` | `HybridSim`: the hybrid model you can touch (`palpate_core::runtime`; ticks release the GIL) |
//! | `haptics.rs` | `HapticLoop`: the servo thread over a hybrid model with a device (`palpate_haptics`; never waits on Python) |
//!
//! The Pythonic layer (file IO, CLI, benchmarks, `palpate.defaults`) lives in `python/palpate/`.

mod body;
mod conv;
mod defaults;
mod errors;
mod haptics;
mod hybrid;
mod hybrid_sim;
mod integrator;
mod material;
mod mesh;
mod meshfree;
mod particles;
mod surface;

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
    m.add_class::<particles::PyParticleBody>()?;
    m.add_class::<hybrid_sim::PyHybridSim>()?;
    m.add_class::<haptics::PyHapticLoop>()?;
    m.add_function(wrap_pyfunction!(errors::memory_budget, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::ellipsoid_wall, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::truncated_ellipsoid_wall, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::box_mesh, m)?)?;
    meshfree::register(m)?;
    surface::register(m)?;
    hybrid::register(m)?;
    defaults::register(m)?;
    Ok(())
}
