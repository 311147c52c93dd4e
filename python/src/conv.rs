//! numpy <-> core conversions, with the checks that make a bad argument a clear error: the one
//! conversion layer of the binding (every other file converts through it).
//!
//! * Inputs are numpy arrays or anything `numpy.asarray` accepts (nested lists ...).
//! * Shape errors raise `palpate.ParameterError` (a `ValueError`), dtype errors
//!   `palpate.ParameterTypeError` (a ParameterError and a `TypeError`); both name the argument,
//!   the expected and the actual shape / dtype.
//! * Float arguments accept any real dtype (float64, float32, integers) and are converted to
//!   float64; index arguments accept any integer dtype (never floats or bools, which would hide a
//!   mistake; an index *set* also takes a boolean mask). Non-contiguous arrays (slices,
//!   transposes) are read through their strides and copied: nothing requires C order.
//! * An empty list `[]` (which numpy reads as float64 of shape `(0,)`) is an empty set of rows or
//!   indices wherever rows or indices are expected.
//! * Outputs are fresh C-contiguous float64 / int64 arrays (copies, never views of the state).
//! * Every other argument (a float, a flag, a str or path, a 3-tuple, a palpate class or enum) is
//!   declared `#[pyo3(from_py_with = conv::arg)]`: a wrong type is a `ParameterTypeError` naming
//!   the argument, not pyo3's bare `TypeError` ([`arg`]).

use std::collections::HashSet;

use numpy::ndarray::{Array1, Array2, ArrayD, IxDyn};
use numpy::{Element, IntoPyArray, PyArray1, PyArray2, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use palpate_core::Vec3;
use pyo3::prelude::*;

/// Any other argument (a number, a flag, a string or path, a 3-vector given as a tuple, a palpate
/// class or enum), converted by pyo3 as its Rust type says, but a wrong type is a
/// `palpate.ParameterTypeError` (a PalpateError that is also a TypeError) instead of pyo3's bare
/// `TypeError`. Used as `#[pyo3(from_py_with = conv::arg)] dt: f64`: the argument keeps its type,
/// its default and its text signature; pyo3 names the argument (errors.rs puts it in the message).
/// Errors that are not about the type (an OverflowError, a ValueError) pass through unchanged.
pub fn arg<'a, 'py, T: FromPyObject<'a, 'py>>(obj: &'a Bound<'py, PyAny>) -> PyResult<T> {
    obj.extract::<T>().map_err(|e| retyped(obj, e.into()))
}

/// pyo3's bare `TypeError` for `obj` (its message names the type received) as a
/// `palpate.ParameterTypeError` that also shows the value; any other error unchanged.
pub fn retyped(obj: &Bound<'_, PyAny>, e: PyErr) -> PyErr {
    let py = obj.py();
    if !e.get_type(py).is(py.get_type::<pyo3::exceptions::PyTypeError>()) {
        return e;
    }
    let r = obj.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into());
    let r = if r.chars().count() > 40 { format!("{}...", r.chars().take(37).collect::<String>()) } else { r };
    crate::errors::type_error(format!("{} (got {r})", e.value(py)))
}

/// `obj` as a numpy array (converted with `numpy.asarray` if it is not one already).
/// Something that is not an array and not numbers (a str, None, a dict, a list of str: numpy
/// makes them str or object arrays) is a `ParameterTypeError` here, before a shape check would
/// call it a shape error; an array of another dtype is refused with its dtype by the callers.
pub fn as_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        return Ok(a.clone());
    }
    let not_numbers = || crate::errors::type_error(format!("{what} must be an array-like of numbers, got {}", type_name(obj)));
    let np = obj.py().import("numpy")?;
    let conv = np
        .call_method1("asarray", (obj,))
        .map_err(|e| crate::errors::type_error(format!("{what} must be an array-like of numbers, got {} ({e})", type_name(obj))))?;
    let a = conv.cast_into::<PyUntypedArray>().map_err(|_| not_numbers())?;
    if !matches!(a.dtype().kind(), b'b' | b'i' | b'u' | b'f') {
        return Err(crate::errors::type_error(format!(
            "{what} must be an array-like of numbers, got {} (numpy reads it as dtype {})",
            type_name(obj),
            dtype_str(&a)
        )));
    }
    Ok(a)
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into())
}

fn shape_str(shape: &[usize]) -> String {
    match shape.len() {
        1 => format!("({},)", shape[0]),
        _ => format!("({})", shape.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

fn dtype_str(a: &Bound<'_, PyUntypedArray>) -> String {
    a.dtype().str().map(|s| s.to_string()).unwrap_or_else(|_| "?".into())
}

/// Copy an array of element type `T` (any strides) into a flat row-major `Vec`.
fn flat<T: Element + Copy, U>(a: &Bound<'_, PyUntypedArray>, f: impl Fn(T) -> U) -> Option<Vec<U>> {
    let typed = a.cast::<PyArrayDyn<T>>().ok()?;
    let ro = typed.try_readonly().ok()?;
    let view = ro.as_array();
    Some(view.iter().map(|&x| f(x)).collect())
}

/// How a real-valued argument is described in a dtype error: `"{what} {REAL_ROWS}, got dtype ..."`.
const REAL_ROWS: &str = "must hold real numbers (float64 preferred)";
/// The same for a 1-D argument of one value per item.
const REAL_VALUES: &str = "must be real numbers";

/// The elements of a real-valued array as f64, or a TypeError `"{what} {says}, got dtype ..."`.
fn to_f64(a: &Bound<'_, PyUntypedArray>, what: &str, says: &str) -> PyResult<Vec<f64>> {
    let out = match a.dtype().kind() {
        b'f' => flat::<f64, _>(a, |x| x).or_else(|| flat::<f32, _>(a, |x| x as f64)),
        b'i' => flat::<i64, _>(a, |x| x as f64)
            .or_else(|| flat::<i32, _>(a, |x| x as f64))
            .or_else(|| flat::<i16, _>(a, |x| x as f64))
            .or_else(|| flat::<i8, _>(a, |x| x as f64)),
        b'u' => flat::<u64, _>(a, |x| x as f64)
            .or_else(|| flat::<u32, _>(a, |x| x as f64))
            .or_else(|| flat::<u16, _>(a, |x| x as f64))
            .or_else(|| flat::<u8, _>(a, |x| x as f64)),
        _ => None,
    };
    out.ok_or_else(|| crate::errors::type_error(format!("{what} {says}, got dtype {}", dtype_str(a))))
}

/// The elements of an integer array as i64 (u64 above i64::MAX saturates, so it is reported as
/// out of range rather than wrapped), or a TypeError naming the dtype.
fn to_i64(a: &Bound<'_, PyUntypedArray>, what: &str) -> PyResult<Vec<i64>> {
    let kind = a.dtype().kind();
    let out = match kind {
        b'i' => flat::<i64, _>(a, |x| x)
            .or_else(|| flat::<i32, _>(a, |x| x as i64))
            .or_else(|| flat::<i16, _>(a, |x| x as i64))
            .or_else(|| flat::<i8, _>(a, |x| x as i64)),
        b'u' => flat::<u64, _>(a, |x| i64::try_from(x).unwrap_or(i64::MAX))
            .or_else(|| flat::<u32, _>(a, |x| x as i64))
            .or_else(|| flat::<u16, _>(a, |x| x as i64))
            .or_else(|| flat::<u8, _>(a, |x| x as i64)),
        _ => None,
    };
    out.ok_or_else(|| {
        let hint = if kind == b'f' { " (convert with .astype(np.int64) if the values are whole)" } else { "" };
        crate::errors::type_error(format!("{what} must be an integer array, got dtype {}{hint}", dtype_str(a)))
    })
}

/// Check `a` has shape `(rows, cols)` (any `rows` if `None`); `form` describes it for the message.
fn check_2d(a: &Bound<'_, PyUntypedArray>, what: &str, rows: Option<usize>, cols: usize, form: &str) -> PyResult<usize> {
    let shape = a.shape();
    let ok = shape.len() == 2 && shape[1] == cols && rows.is_none_or(|r| shape[0] == r);
    if !ok {
        return Err(crate::errors::param_error_from(format!("{what} must have shape {form}, got {}", shape_str(shape))));
    }
    Ok(shape[0])
}

/// Points / positions `(n, 3)` as float64 triples.
pub fn points(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<[f64; 3]>> {
    let a = as_array(obj, what)?;
    check_2d(&a, what, None, 3, "(n, 3)")?;
    let v = to_f64(&a, what, REAL_ROWS)?;
    Ok(v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Points `(n, 3)` as `Vec3`.
pub fn points_vec3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Vec3>> {
    Ok(points(obj, what)?.iter().map(|q| Vec3::new(q[0], q[1], q[2])).collect())
}

/// Per-item vectors `(n, 3)` with `n` fixed, as `Vec3`; `finite` also refuses NaN / inf.
pub fn vec3s(obj: &Bound<'_, PyAny>, what: &str, n: usize, finite: bool) -> PyResult<Vec<Vec3>> {
    let a = as_array(obj, what)?;
    check_2d(&a, what, Some(n), 3, &format!("({n}, 3) (one row per node)"))?;
    let v = to_f64(&a, what, REAL_ROWS)?;
    let out: Vec<Vec3> = v.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
    if finite {
        if let Some(i) = out.iter().position(|f| !(f.x.is_finite() && f.y.is_finite() && f.z.is_finite())) {
            return Err(crate::errors::param_error_from(format!("{what}: row {i} is not finite ({}, {}, {})", out[i].x, out[i].y, out[i].z)));
        }
    }
    Ok(out)
}

/// External forces \[N\] `(n, 3)`, one row per node (or particle): finite, each within
/// `palpate_core::limits::MAX_FORCE_N` (1e6 N; why that bound: there). A 1e300 N force was taken
/// and only failed, or not, steps later.
pub fn forces(obj: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<Vec3>> {
    let f = vec3s(obj, what, n, true)?;
    if let Some(i) = f.iter().position(|v| !palpate_core::limits::force_in_bound(v)) {
        return Err(force_error(&format!("{what}: row {i}"), &f[i]));
    }
    Ok(f)
}

/// One force \[N\] (3,): finite and within `palpate_core::limits::MAX_FORCE_N`.
pub fn force(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec3> {
    let f = vec3(obj, what)?;
    if !palpate_core::limits::force_in_bound(&f) {
        return Err(force_error(what, &f));
    }
    Ok(f)
}

fn force_error(what: &str, f: &Vec3) -> PyErr {
    let norm = palpate_core::limits::force_magnitude(f);
    crate::errors::param_error_from(format!(
        "{what}: force ({:e}, {:e}, {:e}) N of magnitude {norm:e} N is over the bound of {:e} N (the weight of 100 t; \
         a soft-tissue load is tens of newtons: check the units)",
        f.x,
        f.y,
        f.z,
        palpate_core::limits::MAX_FORCE_N
    ))
}

/// One real value per item, shape `(n,)`; `per` names the item (`"(one per particle)"`).
pub fn reals(obj: &Bound<'_, PyAny>, what: &str, n: usize, per: &str) -> PyResult<Vec<f64>> {
    let a = as_array(obj, what)?;
    if a.shape() != [n] {
        return Err(crate::errors::param_error_from(format!("{what} must have shape ({n},) {per}, got {}", shape_str(a.shape()))));
    }
    to_f64(&a, what, REAL_VALUES)
}

/// Real values of any shape (a scalar is shape `()`), with the shape.
pub fn reals_nd(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<(Vec<f64>, Vec<usize>)> {
    let a = as_array(obj, what)?;
    Ok((to_f64(&a, what, REAL_VALUES)?, a.shape().to_vec()))
}

/// Index rows `(m, K)` as signed indices (the core reports negative / out-of-range ones);
/// `[]` is no rows.
pub fn index_rows<const K: usize>(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<[i64; K]>> {
    let a = as_array(obj, what)?;
    if a.shape() == [0] {
        return Ok(Vec::new());
    }
    check_2d(&a, what, None, K, &format!("(m, {K})"))?;
    let v = to_i64(&a, what)?;
    Ok(v.chunks_exact(K).map(|c| std::array::from_fn(|k| c[k])).collect())
}

/// One 3-vector (a sequence or array of 3 real numbers), finite.
pub fn vec3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec3> {
    let a = as_array(obj, what)?;
    if a.shape() != [3] {
        return Err(crate::errors::param_error_from(format!("{what} must be 3 numbers (x, y, z), got shape {}", shape_str(a.shape()))));
    }
    let v = to_f64(&a, what, REAL_ROWS)?;
    if !v.iter().all(|x| x.is_finite()) {
        return Err(crate::errors::param_error_from(format!("{what} = ({}, {}, {}) is not finite", v[0], v[1], v[2])));
    }
    Ok(Vec3::new(v[0], v[1], v[2]))
}

/// What an index set indexes, for the messages: `"node"` items of `"the mesh"`.
#[derive(Clone, Copy)]
pub struct Items {
    pub item: &'static str,
    pub owner: &'static str,
}

pub const NODES: Items = Items { item: "node", owner: "the mesh" };
pub const PARTICLES: Items = Items { item: "particle", owner: "the body" };

/// An index set: a 1-D integer array-like in `0..n`, or a boolean mask of length `n`; `[]` (of
/// any dtype) is the empty set. With `unique`, an index listed twice is an error.
pub fn indices(obj: &Bound<'_, PyAny>, what: &str, n: usize, of: Items, unique: bool) -> PyResult<Vec<usize>> {
    let Items { item, owner } = of;
    let a = as_array(obj, what)?;
    let shape = a.shape().to_vec();
    if shape.len() != 1 {
        return Err(crate::errors::param_error_from(format!(
            "{what} must be a 1-D array of {item} indices (or a boolean mask of length {n}), got shape {}",
            shape_str(&shape)
        )));
    }
    if shape[0] == 0 {
        return Ok(Vec::new()); // `[]` arrives as float64: an empty list of indices is still fine
    }
    if a.dtype().kind() == b'b' {
        if shape[0] != n {
            return Err(crate::errors::param_error_from(format!("{what}: a boolean mask must have length {n} (one per {item}), got {}", shape[0])));
        }
        let mask = flat::<bool, _>(&a, |x| x).ok_or_else(|| crate::errors::type_error(format!("{what}: unreadable boolean mask")))?;
        return Ok(mask.iter().enumerate().filter(|(_, &m)| m).map(|(i, _)| i).collect());
    }
    let idx = to_i64(&a, what)?
        .into_iter()
        .map(|i| {
            if i < 0 || i as u64 >= n as u64 {
                Err(crate::errors::param_error_from(format!("{what}: {item} index {i} out of range ({owner} has {n} {item}s)")))
            } else {
                Ok(i as usize)
            }
        })
        .collect::<PyResult<Vec<usize>>>()?;
    if unique {
        let mut seen = HashSet::with_capacity(idx.len());
        if let Some(&i) = idx.iter().find(|&&i| !seen.insert(i)) {
            return Err(crate::errors::param_error_from(format!("{what}: {item} {i} is listed more than once")));
        }
    }
    Ok(idx)
}

/// Node indices (`indices` of the mesh's nodes, repeats allowed).
pub fn node_indices(obj: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<usize>> {
    indices(obj, what, n, NODES, false)
}

/// Small integer codes, 1-D (e.g. a part per triangle): any integer dtype, or floats with whole
/// values; `form` says what is expected.
pub fn codes(obj: &Bound<'_, PyAny>, what: &str, form: &str) -> PyResult<Vec<i64>> {
    let bad = || crate::errors::param_error_from(format!("{what}: expected {form}"));
    let a = as_array(obj, what)?;
    if a.shape().len() != 1 {
        return Err(bad());
    }
    if a.dtype().kind() == b'f' {
        let v = to_f64(&a, what, REAL_VALUES)?;
        return v.iter().map(|&x| if x.fract() == 0.0 && x.abs() < 1e15 { Ok(x as i64) } else { Err(bad()) }).collect();
    }
    to_i64(&a, what).map_err(|_| bad())
}

/// `(n, 3)` float64 array from vectors.
pub fn vec3s_to_py<'py>(py: Python<'py>, v: &[Vec3]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = v.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    Array2::from_shape_vec((v.len(), 3), flat).expect("n x 3").into_pyarray(py)
}

/// `(3,)` float64 array from one vector.
pub fn vec3_to_py<'py>(py: Python<'py>, v: Vec3) -> Bound<'py, PyArray1<f64>> {
    f64s_to_py(py, &[v.x, v.y, v.z])
}

/// `(m, k)` int64 array from index rows.
pub fn index_rows_to_py<'py, const K: usize>(py: Python<'py>, rows: &[[usize; K]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = rows.iter().flat_map(|r| r.map(|i| i as i64)).collect();
    Array2::from_shape_vec((rows.len(), K), flat).expect("m x k").into_pyarray(py)
}

/// `(m, k)` float64 array from rows.
pub fn f64_rows_to_py<'py, const K: usize>(py: Python<'py>, rows: &[[f64; K]]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    Array2::from_shape_vec((rows.len(), K), flat).expect("m x k").into_pyarray(py)
}

/// 1-D float64 array.
pub fn f64s_to_py<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    Array1::from_vec(v.to_vec()).into_pyarray(py)
}

/// float64 array of any shape.
pub fn f64s_nd_to_py<'py>(py: Python<'py>, v: Vec<f64>, shape: &[usize]) -> Bound<'py, PyArrayDyn<f64>> {
    ArrayD::from_shape_vec(IxDyn(shape), v).expect("shape").into_pyarray(py)
}

/// 1-D int64 array.
pub fn usizes_to_py<'py>(py: Python<'py>, v: &[usize]) -> Bound<'py, PyArray1<i64>> {
    Array1::from_vec(v.iter().map(|&i| i as i64).collect()).into_pyarray(py)
}

/// 1-D int64 array from 32-bit indices.
pub fn u32s_to_py<'py>(py: Python<'py>, v: &[u32]) -> Bound<'py, PyArray1<i64>> {
    Array1::from_vec(v.iter().map(|&i| i as i64).collect()).into_pyarray(py)
}

/// The indices where `flags` is set, as a 1-D int64 array (ascending).
pub fn flagged_to_py<'py>(py: Python<'py>, flags: &[bool]) -> Bound<'py, PyArray1<i64>> {
    let idx: Vec<usize> = flags.iter().enumerate().filter(|(_, &f)| f).map(|(i, _)| i).collect();
    usizes_to_py(py, &idx)
}

/// The extent of `points` \[m\] as `"0.052 x 0.052 x 0.084"` (4 significant digits): a repr that
/// shows at once a mesh read in the wrong unit (issue 37).
pub fn extent_text(points: &[Vec3]) -> String {
    let (lo, hi) = palpate_core::runtime::scale::bounding_box(points);
    if points.is_empty() {
        return "0 x 0 x 0".to_string();
    }
    let e = hi - lo;
    use palpate_core::runtime::scale::sig;
    format!("{} x {} x {}", sig(e.x), sig(e.y), sig(e.z))
}
