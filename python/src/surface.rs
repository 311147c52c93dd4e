//! `palpate.TriSurface`, `ellipsoid_surface`, `sample_inside`, `sample_between`
//! (`palpate_core::mesh::{surface, sample}`); their errors are `palpate.SurfaceError`
//! (errors.rs). Validation, the per-point queries on many points and sampling release the GIL.

use numpy::ndarray::Array1;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyUntypedArrayMethods};
use palpate_core::mesh::{self, TriSurface};
use palpate_core::Vec3;
use pyo3::prelude::*;
use pyo3::IntoPyObjectExt;

use crate::conv;
use crate::errors::{self, surface_error};

/// Register the surface class, the ellipsoid generator and the samplers.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTriSurface>()?;
    m.add_function(wrap_pyfunction!(ellipsoid_surface, m)?)?;
    m.add_function(wrap_pyfunction!(sample_inside, m)?)?;
    m.add_function(wrap_pyfunction!(sample_between, m)?)?;
    Ok(())
}

/// A closed, manifold triangle surface [m], validated in the Rust core.
///
/// ``TriSurface(points, triangles, *, source=None)``
///
/// Parameters
/// ----------
/// points : array_like, shape (n, 3)
///     Vertex positions [m].
/// triangles : array_like, shape (m, 3)
///     Vertex indices, 0-based (any integer dtype).
/// source : str, optional
///     Where the arrays came from (a file name), prefixed to error and warning messages.
///
/// Refused with ``SurfaceError`` (naming the triangle / vertex / edge): non-finite vertices,
/// indices out of range, a repeated vertex in a triangle, a degenerate (zero-area) or duplicate
/// triangle, an open surface (an edge used by one triangle), a non-manifold one (an edge used by
/// more than two triangles, or twice in the same direction: inconsistent orientation), no
/// enclosed volume. An inward-oriented surface is reversed with a ``MeshWarning``.
#[pyclass(module = "palpate", name = "TriSurface", frozen)]
pub struct PyTriSurface {
    pub inner: TriSurface,
}

/// Apply `f` to one point (3,) -> Python scalar, or to points (n, 3) -> array (n,).
fn per_point<'py, T: numpy::Element + Copy + IntoPyObject<'py>>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    what: &str,
    f: impl Fn(&Vec3) -> T + Send + Sync,
) -> PyResult<Bound<'py, PyAny>> {
    if conv::as_array(points, what)?.shape() == [3] {
        let p = conv::vec3(points, what)?;
        return f(&p).into_bound_py_any(py);
    }
    let pts = conv::points_vec3(points, what)?;
    let out: Vec<T> = py.detach(|| pts.iter().map(&f).collect());
    Ok(Array1::from_vec(out).into_pyarray(py).into_any())
}

#[pymethods]
impl PyTriSurface {
    #[new]
    #[pyo3(signature = (points, triangles, *, source = None))]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = conv::arg)] source: Option<String>,
    ) -> PyResult<Self> {
        let p = conv::points(points, "points")?;
        let t = conv::index_rows::<3>(triangles, "triangles")?;
        let (surface, warnings) = errors::guard("TriSurface", || Ok(py.detach(|| TriSurface::from_arrays(&p, &t))))?.map_err(|e| match &source {
            Some(s) => surface_error(e.in_file(s.clone())),
            None => surface_error(e),
        })?;
        errors::warn_all(py, source.as_deref(), warnings)?;
        Ok(PyTriSurface { inner: surface })
    }

    /// Vertex positions [m], (n, 3) (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, self.inner.points())
    }

    /// Triangles, int64 (m, 3), outward oriented (counter-clockwise seen from outside).
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, self.inner.triangles())
    }

    /// Number of vertices.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }

    /// Number of triangles.
    #[getter]
    fn n_triangles(&self) -> usize {
        self.inner.n_triangles()
    }

    /// Enclosed volume [m^3] (divergence theorem; positive).
    #[getter]
    fn volume(&self) -> f64 {
        self.inner.volume()
    }

    /// Surface area [m^2].
    #[getter]
    fn area(&self) -> f64 {
        self.inner.area()
    }

    /// ``(lo, hi)``: the axis-aligned bounding box [m] of the vertices in use, two (3,) arrays.
    #[getter]
    fn bounding_box<'py>(&self, py: Python<'py>) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let (lo, hi) = self.inner.bounding_box();
        (conv::vec3_to_py(py, lo), conv::vec3_to_py(py, hi))
    }

    /// Inside test for one point (3,) -> bool, or points (n, 3) -> bool array (n,).
    ///
    /// ``method="winding"`` (default): generalised winding number > 1/2 (O(triangles) per point);
    /// ``method="parity"``: parity of the +z ray's crossings (grid-accelerated, what the samplers use).
    #[pyo3(signature = (points, method = String::from("winding")), text_signature = "($self, points, method=\"winding\")")]
    fn contains<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>, #[pyo3(from_py_with = conv::arg)] method: String) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.inner;
        match method.as_str() {
            "winding" => per_point(py, points, "points", |p| s.contains(p)),
            "parity" => per_point(py, points, "points", |p| s.contains_parity(p)),
            other => Err(crate::errors::param_error_from(format!("method must be 'winding' or 'parity', got {other:?}"))),
        }
    }

    /// Generalised winding number (1 inside, 0 outside, 1/2 on the surface) of one point (3,) ->
    /// float, or of points (n, 3) -> float64 array (n,).
    fn winding_number<'py>(&self, py: Python<'py>, points: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.inner;
        per_point(py, points, "points", |p| s.winding_number(p))
    }

    /// This surface simplified by quadric-error edge collapse (Garland and Heckbert 1997; the
    /// hybrid build's own simplifier of the inner surface) to at most ``triangles`` triangles, or
    /// as far as its safety checks allow (no topology change, no fold, no sliver): a new
    /// validated ``TriSurface``. Used to make the coarse levels of a reference mesh from a fine
    /// organ surface (:func:`palpate.validate.gmsh_wall`). ``ParameterError`` for fewer than 4.
    #[pyo3(signature = (triangles), text_signature = "($self, triangles)")]
    fn simplified(&self, py: Python<'_>, triangles: errors::Int) -> PyResult<PyTriSurface> {
        let target = errors::count(triangles, "triangles")?;
        if target < 4 {
            return Err(crate::errors::param_error_from(format!("triangles must be at least 4, got {target}")));
        }
        let s = &self.inner;
        let (surface, warnings) = errors::guard("TriSurface.simplified", || {
            Ok(py.detach(|| {
                let out = mesh::simplify::simplify(s.points(), s.triangles(), target);
                let p: Vec<[f64; 3]> = out.points.iter().map(|v| [v.x, v.y, v.z]).collect();
                let t: Vec<[i64; 3]> = out.triangles.iter().map(|t| [t[0] as i64, t[1] as i64, t[2] as i64]).collect();
                TriSurface::from_arrays(&p, &t)
            }))
        })?
        .map_err(surface_error)?;
        errors::warn_all(py, None, warnings)?;
        Ok(PyTriSurface { inner: surface })
    }

    /// This surface without its specks: the closed pieces (triangles connected through shared
    /// vertices) enclosing less than ``min_volume_fraction`` of the largest piece's volume, as
    /// a surface repair leaves them (Rodero's ventricle has two, which cross the main piece: a
    /// tet mesher refuses it). A cavity (an inward piece) counts by its volume's magnitude, so
    /// a hollow wall keeps it. The hybrid build drops the same specks (at 1e-3) from a tagged
    /// surface. Returns ``(surface, kept)``: the new validated ``TriSurface`` (vertices
    /// renumbered in their original order) and the original index of each kept triangle,
    /// (m',) int64, to carry per-triangle data. ``ParameterError`` unless
    /// ``0 <= min_volume_fraction < 1``.
    #[pyo3(signature = (min_volume_fraction = palpate_core::hybrid::MIN_PIECE_VOLUME), text_signature = "($self, min_volume_fraction=0.001)")]
    fn without_specks<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = conv::arg)] min_volume_fraction: f64,
    ) -> PyResult<(PyTriSurface, Bound<'py, PyArray1<i64>>)> {
        let s = &self.inner;
        let w = errors::guard("TriSurface.without_specks", || Ok(py.detach(|| s.without_specks(min_volume_fraction))))?.map_err(surface_error)?;
        let kept: Vec<i64> = w.kept.iter().map(|&t| t as i64).collect();
        Ok((PyTriSurface { inner: w.surface }, kept.into_pyarray(py)))
    }

    fn __len__(&self) -> usize {
        self.inner.n_triangles()
    }

    fn __repr__(&self) -> String {
        format!(
            "TriSurface(n_vertices={}, n_triangles={}, volume={:.6e} m^3, extent {} m)",
            self.inner.n_vertices(),
            self.inner.n_triangles(),
            self.inner.volume(),
            crate::conv::extent_text(self.inner.points())
        )
    }
}

/// The ellipsoid of semi-axes ``semi_axes`` [m] centred at the origin, as a closed outward
/// surface: the octahedron cut ``subdivisions`` times into 4, projected onto the ellipsoid.
/// ``8 * 4**subdivisions`` triangles (default 4: 2048); the volume converges to 4/3 pi a b c.
#[pyfunction]
#[pyo3(signature = (semi_axes = [0.026, 0.026, 0.042], subdivisions = errors::Int::Fits(4)), text_signature = "(semi_axes=..., subdivisions=4)")]
pub fn ellipsoid_surface(py: Python<'_>, #[pyo3(from_py_with = conv::arg)] semi_axes: [f64; 3], subdivisions: errors::Int) -> PyResult<PyTriSurface> {
    let subdivisions = crate::errors::count(subdivisions, "subdivisions")?;
    if !semi_axes.iter().all(|a| a.is_finite() && *a > 0.0) {
        return Err(crate::errors::param_error_from(format!("semi_axes must be finite and positive [m], got {semi_axes:?}")));
    }
    if subdivisions > 9 {
        return Err(crate::errors::param_error_from(format!("subdivisions = {subdivisions} is too many (at most 9: 2 million triangles)")));
    }
    let inner = crate::errors::guard("ellipsoid_surface", || {
        py.detach(|| mesh::surface::try_ellipsoid_surface(semi_axes, subdivisions)).map_err(crate::errors::surface_error)
    })?;
    Ok(PyTriSurface { inner })
}

type Sampled<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<f64>>);

/// Particles on a cubic lattice of ``spacing`` [m] inside ``surface``: returns ``(positions (n, 3)
/// [m], masses (n,) [kg])``, each mass ``density * spacing**3`` (``density`` in kg/m^3). The lattice
/// is centred on the surface's bounding box (half a spacing inside it when the extent is a whole
/// number of spacings). ``ValueError`` for a non-positive spacing / density or a lattice too large.
#[pyfunction]
pub fn sample_inside<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = conv::arg)] surface: Bound<'py, PyTriSurface>,
    #[pyo3(from_py_with = conv::arg)] spacing: f64,
    #[pyo3(from_py_with = conv::arg)] density: f64,
) -> PyResult<Sampled<'py>> {
    let s = &surface.get().inner;
    let set = crate::errors::guard("sample_inside", || py.detach(|| mesh::sample_inside(s, spacing, density)).map_err(surface_error))?;
    Ok((conv::vec3s_to_py(py, &set.positions), conv::f64s_to_py(py, &set.masses)))
}

/// Particles on a cubic lattice of ``spacing`` [m] (over ``outer``'s bounding box) inside
/// ``outer`` and not inside ``inner``: a shell. Returns ``(positions, masses)`` as
/// :func:`sample_inside`. ``SurfaceError`` if a vertex of ``inner`` is not inside ``outer``.
#[pyfunction]
pub fn sample_between<'py>(
    py: Python<'py>,
    #[pyo3(from_py_with = conv::arg)] inner: Bound<'py, PyTriSurface>,
    #[pyo3(from_py_with = conv::arg)] outer: Bound<'py, PyTriSurface>,
    #[pyo3(from_py_with = conv::arg)] spacing: f64,
    #[pyo3(from_py_with = conv::arg)] density: f64,
) -> PyResult<Sampled<'py>> {
    let (i, o) = (&inner.get().inner, &outer.get().inner);
    let set = crate::errors::guard("sample_between", || py.detach(|| mesh::sample_between(i, o, spacing, density)).map_err(surface_error))?;
    Ok((conv::vec3s_to_py(py, &set.positions), conv::f64s_to_py(py, &set.masses)))
}
