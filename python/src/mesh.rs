//! `palpate.TetMesh` and the tet-mesh generators (`crates/palpate-core/src/mesh/`).

use numpy::{PyArray1, PyArray2};
use palpate_core::mesh::generate::{self, EllipsoidWall, TruncatedEllipsoidWall};
use palpate_core::TetMesh;
use pyo3::prelude::*;

use crate::conv;
use crate::errors;

/// A validated mesh of linear tetrahedra.
///
/// ``TetMesh(points, tets, *, source=None)``
///
/// Parameters
/// ----------
/// points : array_like, shape (n, 3)
///     Node positions [m] (any real dtype; stored as float64).
/// tets : array_like, shape (m, 4)
///     Node indices of each tet, 0-based (any integer dtype).
/// source : str, optional
///     Where the arrays came from (a file name), prefixed to error and warning messages.
///
/// Validation (in the Rust core): finite coordinates, indices in range, no repeated node in a
/// tet, no degenerate (flat) tet, no duplicate tet, no unused node. Inverted tets are
/// reoriented (last two nodes swapped) with a ``palpate.MeshWarning``.
///
/// Raises
/// ------
/// MeshError
///     A defect, naming the tet or node (also as attributes ``.tet`` / ``.node``).
/// TypeError, ValueError
///     Wrong dtype or shape.
#[pyclass(module = "palpate", name = "TetMesh", frozen)]
pub struct PyTetMesh {
    pub inner: TetMesh,
}

impl PyTetMesh {
    pub fn from_core(inner: TetMesh) -> Self {
        PyTetMesh { inner }
    }
}

#[pymethods]
impl PyTetMesh {
    #[new]
    #[pyo3(signature = (points, tets, *, source = None))]
    fn new(py: Python<'_>, points: &Bound<'_, PyAny>, tets: &Bound<'_, PyAny>, #[pyo3(from_py_with = conv::arg)] source: Option<String>) -> PyResult<Self> {
        let p = conv::points(points, "points")?;
        let t = conv::index_rows::<4>(tets, "tets")?;
        let (mesh, warnings) = errors::guard("TetMesh", || Ok(TetMesh::from_arrays(&p, &t)))?.map_err(|e| match &source {
            Some(s) => errors::mesh_error(e.in_file(s.clone())),
            None => errors::mesh_error(e),
        })?;
        errors::warn_all(py, source.as_deref(), warnings)?;
        Ok(PyTetMesh { inner: mesh })
    }

    /// Node positions [m], float64 array of shape (n, 3) (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, self.inner.points())
    }

    /// Tets as 0-based node indices, int64 array of shape (m, 4), positively oriented (a copy).
    #[getter]
    fn tets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, self.inner.tets())
    }

    /// Number of nodes n.
    #[getter]
    fn n_nodes(&self) -> usize {
        self.inner.n_nodes()
    }

    /// Number of tets m.
    #[getter]
    fn n_tets(&self) -> usize {
        self.inner.n_tets()
    }

    /// Total volume [m^3].
    #[getter]
    fn volume(&self) -> f64 {
        self.inner.volume()
    }

    /// Smallest dihedral angle over all tets [degrees] (a quality measure; a regular tet has 70.5).
    #[getter]
    fn min_dihedral_deg(&self) -> f64 {
        self.inner.min_dihedral_deg()
    }

    /// Boundary triangles (faces of exactly one tet), oriented outward: int64 array (k, 3).
    fn boundary_faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.inner.boundary_faces())
    }

    /// Indices of the nodes with z <= z_cut + tol [m] (int64, ascending): e.g. the base to fix.
    #[pyo3(signature = (z_cut = 0.0, tol = 1e-9))]
    fn nodes_below<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = conv::arg)] z_cut: f64,
        #[pyo3(from_py_with = conv::arg)] tol: f64,
    ) -> Bound<'py, PyArray1<i64>> {
        conv::usizes_to_py(py, &generate::base_nodes(&self.inner, z_cut, tol))
    }

    fn __len__(&self) -> usize {
        self.inner.n_tets()
    }

    fn __repr__(&self) -> String {
        format!(
            "TetMesh(n_nodes={}, n_tets={}, volume={:.6e} m^3, extent {} m)",
            self.inner.n_nodes(),
            self.inner.n_tets(),
            self.inner.volume(),
            crate::conv::extent_text(self.inner.points())
        )
    }
}

fn axes(v: Option<[f64; 3]>, default: [f64; 3], what: &str) -> PyResult<[f64; 3]> {
    let a = v.unwrap_or(default);
    if !a.iter().all(|x| x.is_finite() && *x > 0.0) {
        return Err(crate::errors::param_error_from(format!("{what} semi-axes must be finite and positive [m], got {a:?}")));
    }
    Ok(a)
}

fn check_shell(inner: [f64; 3], outer: [f64; 3], layers: usize) -> PyResult<()> {
    if !(0..3).all(|i| outer[i] > inner[i]) {
        return Err(crate::errors::param_error_from(format!("outer semi-axes {outer:?} must each exceed the inner ones {inner:?}")));
    }
    if layers == 0 {
        return Err(crate::errors::param_error_from("layers must be at least 1"));
    }
    Ok(())
}

/// Refuse meshes that would not fit in memory (the generators allocate up front).
const MAX_GENERATED_TETS: usize = 20_000_000;

fn check_size(n_tets: Option<usize>) -> PyResult<()> {
    match n_tets {
        Some(n) if n <= MAX_GENERATED_TETS => Ok(()),
        _ => Err(crate::errors::param_error_from(format!("the requested mesh is too large (more than {MAX_GENERATED_TETS} tets)"))),
    }
}

/// The paper's closed ellipsoid wall: the region between two concentric ellipsoids, a geodesic
/// sphere extruded in ``layers`` layers of prisms cut into 3 tets each.
///
/// Parameters
/// ----------
/// inner, outer : (3,) float, optional
///     Semi-axes [m] along x, y, z; default (0.020, 0.020, 0.035) and (0.026, 0.026, 0.042).
/// subdivisions : int, optional
///     Octahedron refinements (default 1): ``8 * 4**s`` triangles per surface.
/// layers : int, optional
///     Tet layers across the wall (default 2).
///
/// The default is the paper's "Ellipsoids Model" (Table 1, about 188 tets): 192 tets, 54 nodes.
/// ``3 * layers * 8 * 4**subdivisions`` tets.
#[pyfunction]
#[pyo3(signature = (inner = None, outer = None, subdivisions = None, layers = None))]
pub fn ellipsoid_wall(
    py: Python<'_>,
    #[pyo3(from_py_with = conv::arg)] inner: Option<[f64; 3]>,
    #[pyo3(from_py_with = conv::arg)] outer: Option<[f64; 3]>,
    subdivisions: Option<errors::Int>,
    layers: Option<errors::Int>,
) -> PyResult<PyTetMesh> {
    let (subdivisions, layers) = (errors::count_opt(subdivisions, "subdivisions")?, errors::count_opt(layers, "layers")?);
    let d = EllipsoidWall::default();
    let p = EllipsoidWall {
        inner: axes(inner, d.inner, "inner")?,
        outer: axes(outer, d.outer, "outer")?,
        subdivisions: subdivisions.unwrap_or(d.subdivisions),
        layers: layers.unwrap_or(d.layers),
    };
    check_shell(p.inner, p.outer, p.layers)?;
    check_size(4usize.checked_pow(p.subdivisions.min(64) as u32).and_then(|f| f.checked_mul(24)).and_then(|f| f.checked_mul(p.layers)))?;
    errors::guard("ellipsoid_wall", || Ok(PyTetMesh::from_core(py.detach(|| generate::try_ellipsoid_wall(&p)).map_err(errors::mesh_error)?)))
}

/// The left-ventricle-like wall: between two concentric ellipsoids, above the plane z = z_cut.
///
/// Parameters
/// ----------
/// inner, outer : (3,) float, optional
///     Semi-axes [m]; default (0.020, 0.020, 0.035) and (0.026, 0.026, 0.042).
/// z_cut : float, optional
///     Base plane height [m] (default 0.0), strictly inside (-inner[2], inner[2]).
/// circumferential : int, optional
///     Points per ring, at least 3 (default 20).
/// longitudinal : int, optional
///     Rings from the base to the apex (default 6).
/// layers : int, optional
///     Tet layers across the wall (default 2).
///
/// ``3 * layers * C * (2L - 1)`` tets; the default has 1320 tets and 363 nodes. Base nodes lie
/// exactly on z = z_cut (find them with ``mesh.nodes_below(z_cut)``).
#[pyfunction]
#[pyo3(signature = (inner = None, outer = None, z_cut = None, circumferential = None, longitudinal = None, layers = None))]
pub fn truncated_ellipsoid_wall(
    py: Python<'_>,
    #[pyo3(from_py_with = conv::arg)] inner: Option<[f64; 3]>,
    #[pyo3(from_py_with = conv::arg)] outer: Option<[f64; 3]>,
    #[pyo3(from_py_with = conv::arg)] z_cut: Option<f64>,
    circumferential: Option<errors::Int>,
    longitudinal: Option<errors::Int>,
    layers: Option<errors::Int>,
) -> PyResult<PyTetMesh> {
    let (circumferential, longitudinal, layers) = (
        errors::count_opt(circumferential, "circumferential")?,
        errors::count_opt(longitudinal, "longitudinal")?,
        errors::count_opt(layers, "layers")?,
    );
    let d = TruncatedEllipsoidWall::default();
    let p = TruncatedEllipsoidWall {
        inner: axes(inner, d.inner, "inner")?,
        outer: axes(outer, d.outer, "outer")?,
        z_cut: z_cut.unwrap_or(d.z_cut),
        circumferential: circumferential.unwrap_or(d.circumferential),
        longitudinal: longitudinal.unwrap_or(d.longitudinal),
        layers: layers.unwrap_or(d.layers),
    };
    check_shell(p.inner, p.outer, p.layers)?;
    if !(p.z_cut.is_finite() && p.z_cut.abs() < p.inner[2]) {
        return Err(crate::errors::param_error_from(format!(
            "z_cut = {} m must lie strictly inside the inner ellipsoid's z range (-{c}, {c})",
            p.z_cut,
            c = p.inner[2]
        )));
    }
    if p.circumferential < 3 {
        return Err(crate::errors::param_error_from(format!("circumferential must be at least 3, got {}", p.circumferential)));
    }
    if p.longitudinal < 1 {
        return Err(crate::errors::param_error_from("longitudinal must be at least 1"));
    }
    check_size(
        p.circumferential
            .checked_mul(2 * p.longitudinal.min(usize::MAX / 4) - 1)
            .and_then(|t| t.checked_mul(3))
            .and_then(|t| t.checked_mul(p.layers)),
    )?;
    errors::guard("truncated_ellipsoid_wall", || {
        Ok(PyTetMesh::from_core(py.detach(|| generate::try_truncated_ellipsoid_wall(&p)).map_err(errors::mesh_error)?))
    })
}

/// The box [0, sx] x [0, sy] x [0, sz] [m] cut into nx * ny * nz cells of 6 tets each.
///
/// Parameters
/// ----------
/// size : (3,) float
///     Edge lengths [m] (default (0.1, 0.02, 0.02): a 10 cm x 2 cm x 2 cm bar).
/// cells : (3,) int
///     Cells per axis (default (10, 2, 2)).
///
/// ``6 nx ny nz`` tets, ``(nx+1)(ny+1)(nz+1)`` nodes; node (i, j, k) has index
/// ``i + (nx+1) * (j + (ny+1) * k)``.
#[pyfunction]
#[pyo3(signature = (size = [0.1, 0.02, 0.02], cells = [errors::Int::Fits(10), errors::Int::Fits(2), errors::Int::Fits(2)]))]
pub fn box_mesh(
    py: Python<'_>,
    #[pyo3(from_py_with = conv::arg)] size: [f64; 3],
    #[pyo3(from_py_with = conv::arg)] cells: [errors::Int; 3],
) -> PyResult<PyTetMesh> {
    let cells = [errors::count(cells[0], "cells[0]")?, errors::count(cells[1], "cells[1]")?, errors::count(cells[2], "cells[2]")?];
    if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
        return Err(crate::errors::param_error_from(format!("box size must be finite and positive [m], got {size:?}")));
    }
    if cells.contains(&0) {
        return Err(crate::errors::param_error_from(format!("box needs at least one cell per axis, got {cells:?}")));
    }
    check_size(cells[0].checked_mul(cells[1]).and_then(|c| c.checked_mul(cells[2])).and_then(|c| c.checked_mul(6)))?;
    errors::guard("box_mesh", || Ok(PyTetMesh::from_core(py.detach(|| generate::try_box_mesh(size, cells)).map_err(errors::mesh_error)?)))
}
