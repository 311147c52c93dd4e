//! The meshfree building blocks, as the core has them (`palpate_core::meshfree::{kernel,
//! neighbors}`): `palpate.Kernel` and its values `kernel_value(kernel, r, h)`, the fixed-radius
//! neighbour search `palpate.neighbours(points, radius)`, and the switch between the particle hot
//! loop's copies (`simd_path`, `set_simd_enabled`). The neighbour search releases the GIL.

use numpy::{PyArray1, PyArrayDyn};
use palpate_core::meshfree::neighbors::neighbours_within_limited;
use palpate_core::meshfree::Kernel;
use pyo3::prelude::*;
use pyo3::IntoPyObjectExt;

use crate::conv;

/// Register the kernel, the neighbour search and the SIMD switch.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyKernel>()?;
    m.add_function(wrap_pyfunction!(kernel_value, m)?)?;
    m.add_function(wrap_pyfunction!(neighbours, m)?)?;
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
fn set_simd_enabled(#[pyo3(from_py_with = conv::arg)] enabled: bool) {
    palpate_core::meshfree::set_simd_enabled(enabled)
}

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

fn check_radius(h: f64, what: &str) -> PyResult<()> {
    if h > 0.0 && h.is_finite() {
        Ok(())
    } else {
        Err(crate::errors::param_error_from(format!("{what} = {h} m must be positive and finite")))
    }
}

/// ``W(r, h)`` [1/m^3] of ``kernel`` (a :class:`Kernel`), normalised in 3D (its integral over
/// space is 1), for distances ``r`` [m] (a float -> float, or an array of any shape -> float64
/// array of that shape) and the support radius ``h`` [m] (``W = 0`` for ``r >= h``): the core's
/// own function, the one a ``ParticleBody`` weighs its pairs with.
#[pyfunction]
fn kernel_value<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = conv::arg)] kernel: PyKernel,
    r: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = conv::arg)] h: f64,
) -> PyResult<Bound<'py, PyAny>> {
    check_radius(h, "h")?;
    let k = Kernel::from(kernel);
    let (v, shape) = conv::reals_nd(r, "r")?;
    let w: Vec<f64> = v.iter().map(|&r| k.w(r, h)).collect();
    if shape.is_empty() {
        return w[0].into_bound_py_any(py);
    }
    let out: Bound<'py, PyArrayDyn<f64>> = conv::f64s_nd_to_py(py, w, &shape);
    Ok(out.into_any())
}

/// Compressed rows `(ptr, idx)`, int64.
type Csr<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray1<i64>>);

/// Neighbours of every point within ``radius`` [m] (excluding itself; distance strictly less
/// than ``radius``): the core's cell-grid search (``palpate_core::meshfree::neighbors``), the one
/// a ``ParticleBody`` pairs its particles with. GIL released.
///
/// Returns ``(ptr, idx)``, int64 compressed rows: the neighbours of point ``i`` are
/// ``idx[ptr[i]:ptr[i + 1]]``, ascending; ``ptr`` has shape (n + 1,).
#[pyfunction]
fn neighbours<'py>(py: Python<'py>, points: &Bound<'py, PyAny>, #[pyo3(from_py_with = conv::arg)] radius: f64) -> PyResult<Csr<'py>> {
    check_radius(radius, "radius")?;
    let p = conv::points_vec3(points, "points")?;
    // 40 bytes a pair: the index lists here and the two int64 arrays handed to Python.
    let (ptr, idx) =
        crate::errors::guard("neighbours", || py.detach(|| neighbours_within_limited(&p, radius, 40.0)).map_err(|e| crate::errors::limit_error(&e, None)))?;
    Ok((conv::usizes_to_py(py, &ptr), conv::usizes_to_py(py, &idx)))
}
