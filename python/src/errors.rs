//! Python exceptions: one base, `palpate.PalpateError`, and one subclass per core error enum
//! (`crates/palpate-core/src/error.rs`). Malformed *arguments* (wrong dtype, wrong shape, wrong
//! type) are reported as the usual `TypeError` / `ValueError` by `conv.rs`; everything the core
//! refuses is a `PalpateError`.
//!
//! Structured details ride along as attributes: `MeshError.tet` / `.node` (the offending tet or
//! node, 0-based, or `None`), `SurfaceError.triangle` / `.vertex`, `StepError.node` / `.time`.
//! The whole tree is defined here, once (the other files only convert into it).

use std::ffi::CString;
use std::fmt::Display;

use palpate_core::error as core;
use palpate_core::mesh::SurfaceError as CoreSurfaceError;
use pyo3::exceptions::{PyException, PyOSError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::{create_exception, PyErr};

create_exception!(palpate, PalpateError, PyException, "Base class of every error raised by palpate.");
create_exception!(
    palpate,
    MeshError,
    PalpateError,
    "A mesh (array or file) that cannot be used. The message names the file, the element and the reason; \
     attributes `tet` and `node` hold the offending 0-based tet / node index, or None."
);
create_exception!(palpate, MaterialError, PalpateError, "Material parameters that are not physical.");
create_exception!(
    palpate,
    ModelError,
    PalpateError,
    "A body that cannot be built (fixed node out of range, non-finite gravity, bad integrator settings)."
);
create_exception!(palpate, SolveError, PalpateError, "A static solve that failed (no convergence, singular system).");
create_exception!(
    palpate,
    StepError,
    PalpateError,
    "A time step that could not be completed; the body is left as it was before that step. \
     Attributes `node` and `time` [s] locate a non-finite value when known, else None."
);
create_exception!(palpate, MeshWarning, PyUserWarning, "Something in a mesh was repaired (e.g. inverted tets reoriented).");
create_exception!(
    palpate,
    SurfaceError,
    MeshError,
    "A triangle surface (array or file) that cannot be used, or surfaces that do not nest. The message \
     names the file, the triangle / vertex / edge and the reason; attributes `triangle` and `vertex` hold \
     the offending 0-based index, or None. A subclass of MeshError."
);
create_exception!(
    palpate,
    ModelFileError,
    PalpateError,
    "A compiled-model file that cannot be read: not a palpate model, another format version, truncated or corrupted. The message names the file and the reason."
);

create_exception!(
    palpate,
    HapticsError,
    PalpateError,
    "The haptic loop could not start or run: a device that cannot be opened (a bridge port in use), a recording of another model or version, a loop already started or stopped."
);

/// Register the classes on the module and give the detail attributes a class-level `None`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("PalpateError", py.get_type::<PalpateError>())?;
    m.add("MeshError", py.get_type::<MeshError>())?;
    m.add("MaterialError", py.get_type::<MaterialError>())?;
    m.add("ModelError", py.get_type::<ModelError>())?;
    m.add("SolveError", py.get_type::<SolveError>())?;
    m.add("StepError", py.get_type::<StepError>())?;
    m.add("MeshWarning", py.get_type::<MeshWarning>())?;
    m.add("ModelFileError", py.get_type::<ModelFileError>())?;
    m.add("HapticsError", py.get_type::<HapticsError>())?;
    let surface = py.get_type::<SurfaceError>();
    surface.setattr("triangle", py.None())?;
    surface.setattr("vertex", py.None())?;
    m.add("SurfaceError", surface)?;
    let mesh = py.get_type::<MeshError>();
    mesh.setattr("tet", py.None())?;
    mesh.setattr("node", py.None())?;
    let step = py.get_type::<StepError>();
    step.setattr("node", py.None())?;
    step.setattr("time", py.None())?;
    Ok(())
}

/// Set `name = value` on the exception instance when `value` is known (class default: None).
fn set_attr<'py, V: IntoPyObject<'py>>(py: Python<'py>, err: &PyErr, name: &str, value: Option<V>) {
    if let Some(v) = value {
        // Setting an attribute on a fresh exception instance cannot fail in practice; if it did,
        // the error itself is still raised, only without the detail.
        let _ = err.value(py).setattr(name, v);
    }
}

/// The innermost tet / node a mesh error is about.
fn mesh_location(e: &core::MeshError) -> (Option<usize>, Option<usize>) {
    match e {
        core::MeshError::NonFiniteNode { node, .. } | core::MeshError::UnusedNode { node } => (None, Some(*node)),
        core::MeshError::IndexOutOfRange { tet, .. } | core::MeshError::Degenerate { tet, .. } | core::MeshError::DuplicateTet { tet, .. } => {
            (Some(*tet), None)
        }
        core::MeshError::RepeatedNode { tet, node } => (Some(*tet), Some(*node)),
        core::MeshError::InFile { source, .. } => mesh_location(source),
        _ => (None, None),
    }
}

pub fn mesh_error(e: core::MeshError) -> PyErr {
    let (tet, node) = mesh_location(&e);
    let err = MeshError::new_err(e.to_string());
    Python::attach(|py| {
        set_attr(py, &err, "tet", tet);
        set_attr(py, &err, "node", node);
    });
    err
}

pub fn material_error(e: core::MaterialError) -> PyErr {
    MaterialError::new_err(e.to_string())
}

pub fn model_error(e: core::ModelError) -> PyErr {
    match e {
        core::ModelError::Mesh(m) => mesh_error(m),
        core::ModelError::Material(m) => material_error(m),
        other => ModelError::new_err(other.to_string()),
    }
}

pub fn solve_error(e: core::SolveError) -> PyErr {
    SolveError::new_err(e.to_string())
}

/// A step error; `context` (e.g. "after 12 of 100 steps") is appended to the message.
pub fn step_error(e: core::StepError, context: &str) -> PyErr {
    let (node, time) = match &e {
        core::StepError::NonFinite { node, time, .. } => (Some(*node), Some(*time)),
        core::StepError::NonFiniteForce { node } => (Some(*node), None),
        _ => (None, None),
    };
    let msg = if context.is_empty() { e.to_string() } else { format!("{e} ({context})") };
    let err = StepError::new_err(msg);
    Python::attach(|py| {
        set_attr(py, &err, "node", node);
        set_attr(py, &err, "time", time);
    });
    err
}

fn surface_location(e: &CoreSurfaceError) -> (Option<usize>, Option<usize>) {
    use CoreSurfaceError as E;
    match e {
        E::NonFiniteVertex { vertex, .. } | E::NotNested { vertex, .. } => (None, Some(*vertex)),
        E::IndexOutOfRange { triangle, .. } | E::Degenerate { triangle, .. } | E::DuplicateTriangle { triangle, .. } | E::OpenEdge { triangle, .. } => {
            (Some(*triangle), None)
        }
        E::RepeatedVertex { triangle, vertex } => (Some(*triangle), Some(*vertex)),
        E::InconsistentOrientation { first, .. } => (Some(*first), None),
        E::NonManifoldEdge { triangles, .. } => (triangles.first().copied(), None),
        E::InFile { source, .. } => surface_location(source),
        _ => (None, None),
    }
}

/// A core surface error as a Python exception: bad sampling arguments are `ValueError`, the rest
/// `SurfaceError` with `.triangle` / `.vertex`.
pub fn surface_error(e: CoreSurfaceError) -> PyErr {
    if matches!(e, CoreSurfaceError::Parameter { .. } | CoreSurfaceError::TooLarge { .. }) {
        return PyValueError::new_err(e.to_string());
    }
    let (triangle, vertex) = surface_location(&e);
    let err = SurfaceError::new_err(e.to_string());
    Python::attach(|py| {
        let v = err.value(py);
        if let Some(t) = triangle {
            let _ = v.setattr("triangle", t);
        }
        if let Some(i) = vertex {
            let _ = v.setattr("vertex", i);
        }
    });
    err
}

/// A model-file error: an I/O failure is `OSError`, anything else `ModelFileError`.
pub fn file_error(e: core::ModelFileError) -> PyErr {
    match e {
        core::ModelFileError::Io { .. } => PyOSError::new_err(e.to_string()),
        other => ModelFileError::new_err(other.to_string()),
    }
}

/// Issue each of `warnings` as a `palpate.MeshWarning`, prefixed `"{source}: "` when the arrays
/// came from a file.
pub fn warn_all<W: Display>(py: Python<'_>, source: Option<&str>, warnings: impl IntoIterator<Item = W>) -> PyResult<()> {
    for w in warnings {
        warn(py, match source {
            Some(s) => format!("{s}: {w}"),
            None => w.to_string(),
        })?;
    }
    Ok(())
}

/// Issue `msg` as a `palpate.MeshWarning`.
pub fn warn(py: Python<'_>, msg: String) -> PyResult<()> {
    let msg = CString::new(msg).unwrap_or_else(|_| CString::new("mesh warning").unwrap());
    PyErr::warn(py, &py.get_type::<MeshWarning>(), &msg, 1)
}
