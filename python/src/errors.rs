//! Python exceptions: one base, `palpate.PalpateError`, and one subclass per core error enum
//! (`crates/palpate-core/src/error.rs`). Malformed *arguments* are `ParameterError`s (also
//! `ValueError`s) that keep the builtin class a caller expects: `ParameterTypeError` (also a
//! `TypeError`: wrong dtype, not an array, from `conv.rs`) and `ParameterIndexError` (also an
//! `IndexError`: an index past the end) and `ParameterKeyError` (also a `KeyError`: a state dict
//! without a key); everything the core refuses is a `PalpateError`. An argument of the wrong
//! type (a str where a float goes), which pyo3 converts before palpate's code runs, is a
//! `ParameterTypeError` too: every such argument is read through `conv::arg` (or `Int`), and the
//! argument's name, which pyo3 adds as a note (`while processing 'dt'`), is put in the message
//! (`ParameterTypeError.add_note`, below). Python's own call errors (an unknown keyword, a
//! missing or extra argument) stay `TypeError`s, as for any Python function.
//!
//! Structured details ride along as attributes: `MeshError.tet` / `.node` (the offending tet or
//! node, 0-based, or `None`), `SurfaceError.triangle` / `.vertex`, `StepError.node` / `.time`.
//! The whole tree is defined here, once (the other files only convert into it).

use std::ffi::CString;
use std::fmt::Display;

use palpate_core::error as core;
use palpate_core::mesh::SurfaceError as CoreSurfaceError;
use pyo3::exceptions::{PyException, PyIndexError, PyKeyError, PyOSError, PyOverflowError, PyTypeError, PyUserWarning, PyValueError};
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
create_exception!(palpate, ModelError, PalpateError, "A body that cannot be built (fixed node out of range, non-finite gravity, bad integrator settings).");
create_exception!(palpate, SolveError, PalpateError, "A static solve that failed (no convergence, singular system).");
create_exception!(
    palpate,
    StepError,
    PalpateError,
    "A time step that could not be completed; the body is left as it was before that step. \
     Attributes `node` and `time` [s] locate a non-finite value, or the node past the speed bound of a divergence that has started, when known, else None."
);
create_exception!(palpate, MeshWarning, PyUserWarning, "Something in a mesh was repaired (e.g. inverted tets reoriented).");
create_exception!(
    palpate,
    UnitWarning,
    PyUserWarning,
    "A value most likely given in the wrong unit (palpate's are SI: m, Pa, kg/m^3, s): a Young's modulus outside \
     soft tissue's 100 Pa to 10 MPa, a tool radius over 5 cm, a tool target over 1 m from the organ. The message \
     names the value and the unit that fits; ``strict_units=True`` makes it a ParameterError."
);
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
    LimitError,
    PalpateError,
    "A size from the input (node or element count, voxel grid, neighbour pairs, steps, a file or its \
     decompressed length) over palpate's memory budget, refused before the memory is taken. The message \
     says what was asked, how much and the budget; raise the budget with the environment variable \
     PALPATE_MAX_MEMORY (bytes, or e.g. 16G). Attributes `requested` and `budget` [bytes] hold the numbers, `budget_source` where the budget \
     came from (see `palpate.memory_budget()`)."
);
create_exception!(palpate, LoadWarning, PyUserWarning, "A load that the body will not carry as given (force on fixed nodes, which the solver drops).");
create_exception!(
    palpate,
    InternalError,
    PalpateError,
    "A palpate bug caught at the binding (a Rust panic): the operation was abandoned and nothing it \
     touched should be trusted. The message says where; please report it with the input."
);

/// An integer argument as Python gave it, also one beyond 64 bits: typed `i64`, pyo3 refused
/// `2**70` or `-(2**70)` with its own OverflowError before palpate could name the argument.
/// [`count`], [`count_opt`] and [`index`] take it and turn it into a `usize` or a
/// `palpate.ParameterError` that names the argument. Not an int: a `palpate.ParameterTypeError`,
/// as for any argument of the wrong type (`conv::arg`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Int {
    Fits(i64),
    /// Beyond 64 bits, with its sign.
    Huge {
        negative: bool,
    },
}

impl<'a, 'py> FromPyObject<'a, 'py> for Int {
    type Error = PyErr;
    fn extract(obj: pyo3::Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        match obj.extract::<i64>() {
            Ok(v) => Ok(Int::Fits(v)),
            Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => Ok(Int::Huge { negative: obj.lt(0)? }),
            Err(e) => Err(crate::conv::retyped(&obj, e)),
        }
    }
}

impl std::fmt::Display for Int {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Int::Fits(v) => write!(f, "{v}"),
            Int::Huge { negative: true } => write!(f, "an integer below -2**63"),
            Int::Huge { negative: false } => write!(f, "an integer above 2**63 - 1"),
        }
    }
}

/// A count argument (steps, ticks) that must not be negative, as `usize`: a negative count, or
/// one beyond 64 bits, is a `palpate.ParameterError` naming the argument (pyo3's own conversion
/// raised OverflowError).
pub fn count(v: Int, name: &str) -> PyResult<usize> {
    match v {
        Int::Fits(v) => usize::try_from(v).map_err(|_| param_error(format!("{name} = {v}: must be a count, 0 or more"))),
        neg @ Int::Huge { negative: true } => Err(param_error(format!("{name} = {neg}: must be a count, 0 or more"))),
        // Larger than any count palpate could run or allocate (the budget refuses far less).
        big @ Int::Huge { negative: false } => Err(param_error(format!("{name} = {big}: too large for a count (at most 2**63 - 1)"))),
    }
}

/// [`count`] of an optional argument (None: the default).
pub fn count_opt(v: Option<Int>, name: &str) -> PyResult<Option<usize>> {
    v.map(|v| count(v, name)).transpose()
}

/// An index argument `i` into `n` items: a negative one (or one beyond 64 bits) is a
/// `palpate.ParameterError` (pyo3's conversion to `usize` raised OverflowError); one past the
/// end is a `palpate.ParameterIndexError` (a ParameterError and an IndexError, as for a sequence)
/// saying `what` it indexes and how many there are.
pub fn index(i: Int, n: usize, name: &str, what: &str) -> PyResult<usize> {
    let i = match i {
        Int::Fits(v) => usize::try_from(v).map_err(|_| param_error(format!("{name} = {v}: must be an index, 0 or more")))?,
        Int::Huge { negative: true } => return Err(param_error(format!("{name} = {i}: must be an index, 0 or more"))),
        Int::Huge { negative: false } => return Err(out_of_range(format!("{name} = {i}: out of range ({n} {what})"))),
    };
    if i < n {
        Ok(i)
    } else {
        Err(out_of_range(format!("{name} = {i}: out of range ({n} {what})")))
    }
}

/// An index past the end as `palpate.ParameterIndexError`: a ParameterError and an IndexError.
pub fn out_of_range(msg: String) -> PyErr {
    raise_dynamic(&PARAMETER_INDEX, msg, PyIndexError::new_err)
}

/// An argument of the wrong type or form (a dtype, a shape that is not an array) as
/// `palpate.ParameterTypeError`: a ParameterError and a TypeError.
pub fn type_error(msg: String) -> PyErr {
    raise_dynamic(&PARAMETER_TYPE, msg, PyTypeError::new_err)
}

/// A state dict without `key` as `palpate.ParameterKeyError`: a ParameterError and a KeyError.
pub fn key_error(msg: String) -> PyErr {
    raise_dynamic(&PARAMETER_KEY, msg, PyKeyError::new_err)
}

/// An instance of one of the classes made at registration (`type(name, bases, {})`), or
/// `fallback` before the module is registered.
fn raise_dynamic(class: &pyo3::sync::PyOnceLock<Py<PyAny>>, msg: String, fallback: fn(String) -> PyErr) -> PyErr {
    Python::attach(|py| match class.get(py) {
        Some(t) => match t.bind(py).call1((msg.clone(),)) {
            Ok(inst) => PyErr::from_value(inst),
            Err(_) => fallback(msg),
        },
        None => fallback(msg),
    })
}

/// A bad argument value as `palpate.ParameterError`: a PalpateError that is also a ValueError.
pub fn param_error(msg: String) -> PyErr {
    raise_dynamic(&PARAMETER, msg, PyValueError::new_err)
}

/// [`param_error`] of anything printable (the binding's argument checks).
pub fn param_error_from(msg: impl Into<String>) -> PyErr {
    param_error(msg.into())
}

/// Warn (`palpate.LoadWarning`) when external force falls on fixed nodes: the solver drops it, so
/// the body carries less load than was asked (28 % of a probe's force in one report). `force`
/// gives each loaded node's force; `what` names the call.
pub fn warn_fixed_load(py: Python<'_>, fixed: &[bool], loaded: impl IntoIterator<Item = (usize, f64)>, what: &str) -> PyResult<()> {
    let (mut total, mut dropped, mut nodes) = (0.0, 0.0, Vec::new());
    for (i, f) in loaded {
        total += f;
        if fixed.get(i).copied().unwrap_or(false) && f > 0.0 {
            dropped += f;
            nodes.push(i);
        }
    }
    if nodes.is_empty() {
        return Ok(());
    }
    let share = if total > 0.0 { 100.0 * dropped / total } else { 0.0 };
    let shown: Vec<String> = nodes.iter().take(5).map(|i| i.to_string()).collect();
    let msg = format!(
        "{what}: {} loaded node(s) are fixed (node {}{}): their load is dropped, {share:.1} % of the total force",
        nodes.len(),
        shown.join(", "),
        if nodes.len() > 5 { ", ..." } else { "" }
    );
    let msg = CString::new(msg).unwrap_or_default();
    PyErr::warn(py, &py.get_type::<LoadWarning>(), &msg, 1)
}

static PARAMETER: pyo3::sync::PyOnceLock<Py<PyAny>> = pyo3::sync::PyOnceLock::new();
static PARAMETER_INDEX: pyo3::sync::PyOnceLock<Py<PyAny>> = pyo3::sync::PyOnceLock::new();
static PARAMETER_TYPE: pyo3::sync::PyOnceLock<Py<PyAny>> = pyo3::sync::PyOnceLock::new();
static PARAMETER_KEY: pyo3::sync::PyOnceLock<Py<PyAny>> = pyo3::sync::PyOnceLock::new();

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
    m.add("UnitWarning", py.get_type::<UnitWarning>())?;
    m.add("ModelFileError", py.get_type::<ModelFileError>())?;
    let limit = py.get_type::<LimitError>();
    limit.setattr("requested", py.None())?;
    limit.setattr("budget", py.None())?;
    limit.setattr("budget_source", py.None())?;
    m.add("LimitError", limit)?;
    m.add("InternalError", py.get_type::<InternalError>())?;
    m.add("LoadWarning", py.get_type::<LoadWarning>())?;
    // A model file that cannot be opened or read: both a ModelFileError (a PalpateError) and an
    // OSError (what `except OSError` callers of the earlier API expect).
    let io_type = py.import("builtins")?.getattr("type")?.call1((
        "ModelFileIOError",
        (py.get_type::<ModelFileError>(), py.get_type::<PyOSError>()),
        pyo3::types::PyDict::new(py),
    ))?;
    io_type.setattr("__module__", "palpate")?;
    io_type.setattr(
        "__doc__",
        "A model file that cannot be opened or read (missing, a directory, not a regular file, unreadable): a ModelFileError and an OSError.",
    )?;
    m.add("ModelFileIOError", &io_type)?;
    let _ = MODEL_FILE_IO.set(py, io_type.unbind());
    // An argument palpate refuses (a negative count, a parameter out of range): a PalpateError
    // and a ValueError, so both `except palpate.PalpateError` and `except ValueError` catch it.
    let param_type = py.import("builtins")?.getattr("type")?.call1((
        "ParameterError",
        (py.get_type::<PalpateError>(), py.get_type::<PyValueError>()),
        pyo3::types::PyDict::new(py),
    ))?;
    param_type.setattr("__module__", "palpate")?;
    param_type.setattr("__doc__", "An argument value palpate refuses (negative count, parameter out of range): a PalpateError and a ValueError.")?;
    m.add("ParameterError", &param_type)?;
    // Kinds of ParameterError that also keep the builtin class a Python caller expects: an index
    // past the end (IndexError, as for a sequence), an argument of the wrong type or form
    // (TypeError), a state dict without a key (KeyError).
    for (name, builtin, doc, slot) in [
        ("ParameterIndexError", py.get_type::<PyIndexError>(), "An index argument past the end (a region, a particle): a ParameterError and an IndexError.", &PARAMETER_INDEX),
        ("ParameterTypeError", py.get_type::<PyTypeError>(), "An argument of the wrong type or form (a str where a number goes, not an array of numbers, an integer array of floats): a ParameterError and a TypeError.", &PARAMETER_TYPE),
        ("ParameterKeyError", py.get_type::<PyKeyError>(), "A state dict without a key the body needs (not one from get_state()): a ParameterError and a KeyError.", &PARAMETER_KEY),
    ] {
        let body = pyo3::types::PyDict::new(py);
        if name == "ParameterTypeError" {
            body.set_item("add_note", argument_note(py)?)?;
        }
        let t = py.import("builtins")?.getattr("type")?.call1((name, (&param_type, builtin), body))?;
        t.setattr("__module__", "palpate")?;
        t.setattr("__doc__", doc)?;
        m.add(name, &t)?;
        let _ = slot.set(py, t.unbind());
    }
    let _ = PARAMETER.set(py, param_type.unbind());
    install_panic_hook();
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

/// `ParameterTypeError.add_note`: pyo3 names an argument whose conversion failed by adding the
/// note `while processing 'NAME'` to the error (pyo3 0.30, `argument_extraction_error`); this
/// puts the name at the head of the message instead (`argument 'dt': must be real number, not
/// str (got 'abc')`), on every Python version (add_note is 3.11+). Other notes are notes.
fn argument_note(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    const CODE: &std::ffi::CStr = cr#"
import re

def add_note(self, note, /):
    m = re.fullmatch(r"while processing '(\w+)'", str(note))
    if m and self.args and isinstance(self.args[0], str) and not self.args[0].startswith("argument '"):
        self.args = (f"argument '{m.group(1)}': {self.args[0]}",) + self.args[1:]
    elif hasattr(BaseException, "add_note"):
        BaseException.add_note(self, note)
"#;
    let globals = pyo3::types::PyDict::new(py);
    globals.set_item("__name__", "palpate")?;
    py.run(CODE, Some(&globals), None)?;
    globals.as_any().get_item("add_note")
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
        core::MeshError::IndexOutOfRange { tet, .. }
        | core::MeshError::Degenerate { tet, .. }
        | core::MeshError::DuplicateTet { tet, .. }
        | core::MeshError::CoincidentTet { tet, .. } => (Some(*tet), None),
        core::MeshError::RepeatedNode { tet, node } => (Some(*tet), Some(*node)),
        core::MeshError::InFile { source, .. } => mesh_location(source),
        _ => (None, None),
    }
}

pub fn mesh_error(e: core::MeshError) -> PyErr {
    match &e {
        core::MeshError::Limit(l) => return limit_error(l, None),
        core::MeshError::InFile { file, source } => {
            if let core::MeshError::Limit(l) = source.as_ref() {
                return limit_error(l, Some(file));
            }
        }
        _ => {}
    }
    let (tet, node) = mesh_location(&e);
    let err = MeshError::new_err(e.to_string());
    Python::attach(|py| {
        set_attr(py, &err, "tet", tet);
        set_attr(py, &err, "node", node);
    });
    err
}

/// A memory-budget refusal as `palpate.LimitError`, with `requested` and `budget` [bytes];
/// `prefix` (e.g. a file name) is put before the message.
pub fn limit_error(e: &core::LimitError, prefix: Option<&str>) -> PyErr {
    let msg = match prefix {
        Some(p) => format!("{p}: {e}"),
        None => e.to_string(),
    };
    let err = LimitError::new_err(msg);
    Python::attach(|py| {
        set_attr(py, &err, "requested", Some(e.bytes));
        set_attr(py, &err, "budget", Some(e.budget));
        set_attr(py, &err, "budget_source", Some(e.budget_source.clone()));
    });
    err
}

/// The memory budget of one input-derived structure now, and where it came from.
///
/// Returns ``(bytes, source)``: ``PALPATE_MAX_MEMORY`` when set, else half of the smallest of
/// the process's address-space limit (RLIMIT_AS, less what is mapped), its cgroup's memory
/// limit and the memory available (MemAvailable); 8 GiB when none can be read (not Linux).
/// Read afresh at every call (the memory available changes).
#[pyfunction]
pub fn memory_budget() -> (u64, String) {
    let b = palpate_core::limits::budget();
    (b.bytes, b.source)
}

// ---------------------------------------------------------------------------------------------
// Panics: none may cross into Python as pyo3's PanicException (a BaseException, which
// `except Exception` and `except palpate.PalpateError` both miss). `guard` runs a call under
// catch_unwind and turns a panic into `palpate.InternalError`; the hook keeps the panic's
// message and place for that error instead of printing a Rust backtrace note on stderr (set
// PALPATE_DEBUG=1 to see it printed as well).
// ---------------------------------------------------------------------------------------------

static MODEL_FILE_IO: pyo3::sync::PyOnceLock<Py<PyAny>> = pyo3::sync::PyOnceLock::new();

thread_local! {
    static LAST_PANIC: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

fn install_panic_hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let msg = match (info.payload().downcast_ref::<&str>(), info.payload().downcast_ref::<String>()) {
                (Some(s), _) => s.to_string(),
                (_, Some(s)) => s.clone(),
                _ => "panic".to_string(),
            };
            let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
            LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{msg}{at}")));
            if std::env::var_os("PALPATE_DEBUG").is_some() {
                default(info);
            }
        }));
    });
}

/// Run `f`, turning a panic inside it into `palpate.InternalError` naming `what` (the call).
pub fn guard<T>(what: &str, f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let msg = LAST_PANIC
                .with(|p| p.borrow_mut().take())
                .unwrap_or_else(|| match (payload.downcast_ref::<&str>(), payload.downcast_ref::<String>()) {
                    (Some(s), _) => s.to_string(),
                    (_, Some(s)) => s.clone(),
                    _ => "panic".to_string(),
                });
            Err(InternalError::new_err(format!("{what}: internal error (a palpate bug; please report it with the input): {msg}")))
        }
    }
}

pub fn material_error(e: core::MaterialError) -> PyErr {
    MaterialError::new_err(e.to_string())
}

pub fn model_error(e: core::ModelError) -> PyErr {
    match e {
        core::ModelError::Mesh(m) => mesh_error(m),
        core::ModelError::Material(m) => material_error(m),
        core::ModelError::Limit(l) => limit_error(&l, None),
        other => ModelError::new_err(other.to_string()),
    }
}

pub fn solve_error(e: core::SolveError) -> PyErr {
    SolveError::new_err(e.to_string())
}

/// A step error; `context` (e.g. "after 12 of 100 steps") is appended to the message.
pub fn step_error(e: core::StepError, context: &str) -> PyErr {
    let (node, time) = match &e {
        core::StepError::NonFinite { node, time, .. } | core::StepError::Diverging { node, time, .. } => (Some(*node), Some(*time)),
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
    if let CoreSurfaceError::Limit(l) = &e {
        return limit_error(l, None);
    }
    if matches!(e, CoreSurfaceError::Parameter { .. } | CoreSurfaceError::TooLarge { .. }) {
        return param_error(e.to_string());
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
        // I/O failures stay OSError subclasses for `except OSError` callers, but are also
        // ModelFileError (a PalpateError): see ModelFileIOError in the Python package.
        core::ModelFileError::Io { .. } => Python::attach(|py| match MODEL_FILE_IO.get(py) {
            Some(t) => match t.bind(py).call1((e.to_string(),)) {
                Ok(inst) => PyErr::from_value(inst),
                Err(err) => err,
            },
            None => ModelFileError::new_err(e.to_string()),
        }),
        core::ModelFileError::Limit { path, source } => limit_error(&source, Some(&path)),
        other => ModelFileError::new_err(other.to_string()),
    }
}

/// Issue each of `warnings` as a `palpate.MeshWarning`, prefixed `"{source}: "` when the arrays
/// came from a file.
pub fn warn_all<W: Display>(py: Python<'_>, source: Option<&str>, warnings: impl IntoIterator<Item = W>) -> PyResult<()> {
    for w in warnings {
        warn(
            py,
            match source {
                Some(s) => format!("{s}: {w}"),
                None => w.to_string(),
            },
        )?;
    }
    Ok(())
}

/// Issue `msg` as a `palpate.UnitWarning`, or, with `strict`, return it as a
/// `palpate.ParameterError` (`"{msg} (strict_units)"`).
pub fn unit_check(py: Python<'_>, msg: String, strict: bool) -> PyResult<()> {
    if strict {
        return Err(param_error_from(format!("{msg} (strict_units)")));
    }
    let msg = CString::new(msg).unwrap_or_else(|_| CString::new("unit warning").unwrap());
    PyErr::warn(py, &py.get_type::<UnitWarning>(), &msg, 1)
}

/// The tool target's unit check of a `HybridSim` or a `HapticLoop`: a target more than
/// [`palpate_core::runtime::scale::TOOL_REACH_M`] from the organ's bounding box warns once (or,
/// with `strict`, is refused every time).
pub struct TargetCheck {
    lo: palpate_core::Vec3,
    hi: palpate_core::Vec3,
    /// `strict_units`: refuse rather than warn.
    pub strict: bool,
    warned: std::sync::atomic::AtomicBool,
}

impl TargetCheck {
    /// The check against the box `[lo, hi]` \[m\].
    pub fn new((lo, hi): (palpate_core::Vec3, palpate_core::Vec3), strict: bool) -> TargetCheck {
        TargetCheck { lo, hi, strict, warned: Default::default() }
    }

    /// Check `target` \[m\]; `what` prefixes the message (the call that gave it).
    pub fn check(&self, py: Python<'_>, what: &str, target: &palpate_core::Vec3) -> PyResult<()> {
        use std::sync::atomic::Ordering::Relaxed;
        if self.warned.load(Relaxed) && !self.strict {
            return Ok(());
        }
        if let Some(w) = palpate_core::runtime::scale::target_warning(&self.lo, &self.hi, target) {
            unit_check(py, format!("{what}: {w}"), self.strict)?;
            self.warned.store(true, Relaxed);
        }
        Ok(())
    }
}

impl Clone for TargetCheck {
    fn clone(&self) -> Self {
        TargetCheck { lo: self.lo, hi: self.hi, strict: self.strict, warned: self.warned.load(std::sync::atomic::Ordering::Relaxed).into() }
    }
}

/// Issue `msg` as a `palpate.MeshWarning`.
pub fn warn(py: Python<'_>, msg: String) -> PyResult<()> {
    let msg = CString::new(msg).unwrap_or_else(|_| CString::new("mesh warning").unwrap());
    PyErr::warn(py, &py.get_type::<MeshWarning>(), &msg, 1)
}

/// Ctrl-C for a long computation run with the GIL released: the core asks [`CtrlC::poll`]
/// between iterations (`static_solve_with`, `indent_with`, a body's steps), and at most every
/// 50 ms it takes the GIL and runs Python's signal handlers. A pending `KeyboardInterrupt` (or
/// whatever a handler raised) stops the computation and is raised by [`CtrlC::finish`]. Python
/// runs signal handlers on its main thread only; elsewhere this never interrupts.
pub struct CtrlC {
    last: std::time::Instant,
    err: Option<PyErr>,
}

/// How often the GIL is taken to look for a signal: short against a user's patience, long
/// against the cost of taking the GIL (microseconds).
const CTRL_C_POLL: std::time::Duration = std::time::Duration::from_millis(50);

impl CtrlC {
    pub fn new() -> CtrlC {
        CtrlC { last: std::time::Instant::now(), err: None }
    }

    /// Should the computation stop?
    pub fn poll(&mut self) -> bool {
        if self.err.is_some() {
            return true;
        }
        if self.last.elapsed() < CTRL_C_POLL {
            return false;
        }
        self.last = std::time::Instant::now();
        if let Err(e) = Python::attach(|py| py.check_signals()) {
            self.err = Some(e);
        }
        self.err.is_some()
    }

    /// The signal's exception if the computation was interrupted, else `other`'s conversion.
    pub fn finish<E>(&mut self, other: E, convert: impl FnOnce(E) -> PyErr) -> PyErr {
        self.err.take().unwrap_or_else(|| convert(other))
    }
}
