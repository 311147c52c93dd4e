//! `palpate.HybridModel`: the compiled hybrid model (FEM core, particle shell, skin, activation
//! regions) built from the surfaces of an organ wall, saved and loaded as one file.

use crate::conv;
use crate::errors;
use crate::errors::{file_error, surface_error};
use crate::surface::PyTriSurface;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use palpate_core::hybrid::{self, HybridModel, HybridOptions, Projection, Spacing, VoxelLabel, Wall, WallPart};
use palpate_core::mesh::TriSurface;
use palpate_core::HybridError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyProjection>()?;
    m.add_class::<PyHybridModel>()?;
    m.add_function(wrap_pyfunction!(ventricle_surface, m)?)?;
    Ok(())
}

/// The synthetic truncated ventricle of the benchmark protocol as one closed surface tagged
/// inner / outer / base (``palpate_core::hybrid::shapes::truncated_ventricle``): the wall between
/// the ellipsoids of semi-axes (20, 20, 35) mm and (26, 26, 42) mm above z = 0, with
/// ``circumferential`` x ``longitudinal`` points per surface. Returns ``(points (n, 3) [m],
/// triangles (m, 3) int64, part (m,) int8: 0 inner, 1 outer, 2 base)``.
#[pyfunction]
#[pyo3(signature = (circumferential = errors::Int::Fits(96), longitudinal = errors::Int::Fits(24)), text_signature = "(circumferential=96, longitudinal=24)")]
fn ventricle_surface<'py>(py: Python<'py>, circumferential: errors::Int, longitudinal: errors::Int) -> PyResult<TaggedSurface<'py>> {
    let (circumferential, longitudinal) = (errors::count(circumferential, "circumferential")?, errors::count(longitudinal, "longitudinal")?);
    if !(3..=4096).contains(&circumferential) || !(1..=4096).contains(&longitudinal) {
        return Err(crate::errors::param_error_from(format!(
            "circumferential must be 3 to 4096 and longitudinal 1 to 4096, got {circumferential} and {longitudinal}"
        )));
    }
    let p = palpate_core::mesh::generate::TruncatedEllipsoidWall { circumferential, longitudinal, ..Default::default() };
    let wall = errors::guard("ventricle_surface", || py.detach(|| hybrid::shapes::truncated_ventricle(&p)).map_err(hybrid_error))?;
    let parts: Vec<i8> = wall.parts.iter().map(|&w| w as u8 as i8).collect();
    Ok((conv::vec3s_to_py(py, wall.surface.points()), conv::index_rows_to_py(py, wall.surface.triangles()), PyArray1::from_vec(py, parts)))
}

/// Points (n, 3), triangles (m, 3) and a part per triangle (m,), as numpy arrays.
type TaggedSurface<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>, Bound<'py, PyArray1<i8>>);

fn hybrid_error(e: HybridError) -> PyErr {
    match e {
        HybridError::Surface(s) => surface_error(s),
        HybridError::Mesh(m) => errors::mesh_error(m),
        HybridError::Parameter { .. } => crate::errors::param_error_from(e.to_string()),
        HybridError::Limit(l) => errors::limit_error(&l, None),
        other => errors::ModelError::new_err(other.to_string()),
    }
}

/// How the builder projects between the outer surface and the core.
#[pyclass(name = "Projection", module = "palpate", eq, eq_int, hash, frozen, from_py_object)]
#[derive(Clone, Copy, PartialEq, Hash)]
#[allow(clippy::upper_case_acronyms)] // the Python names (palpate.Projection.RADIAL)
pub enum PyProjection {
    /// Along the streamlines of the transmural harmonic field (any wall shape; default).
    TRANSMURAL,
    /// The paper's: along straight lines through the wall's mass centre (star-shaped walls).
    RADIAL,
}

impl From<Projection> for PyProjection {
    fn from(p: Projection) -> Self {
        match p {
            Projection::Transmural => PyProjection::TRANSMURAL,
            Projection::Radial => PyProjection::RADIAL,
        }
    }
}

impl From<PyProjection> for Projection {
    fn from(p: PyProjection) -> Self {
        match p {
            PyProjection::TRANSMURAL => Projection::Transmural,
            PyProjection::RADIAL => Projection::Radial,
        }
    }
}

/// A compiled hybrid model. Build it with :meth:`HybridModel.build_nested` (two nested closed
/// surfaces) or :meth:`HybridModel.build_tagged` (one closed surface, a part per triangle), or
/// :meth:`HybridModel.load` a saved one. Everything is in SI units (m, kg), world frame of the
/// input surfaces; arrays are copies.
#[pyclass(name = "HybridModel", module = "palpate", frozen)]
pub struct PyHybridModel {
    pub model: HybridModel,
}

/// The build options from keyword arguments; each one not given is the core's
/// (`HybridOptions::default()`, also `palpate.defaults.hybrid`).
fn options(kw: Option<&Bound<'_, PyDict>>) -> PyResult<HybridOptions> {
    let mut o = HybridOptions::default();
    let (mut spacing, mut particles) = (None, None);
    for (k, v) in kw.into_iter().flatten() {
        let key: String = k.extract()?;
        let arg = |e: PyErr| errors::type_error(format!("argument '{key}': {e}"));
        match key.as_str() {
            "projection" => o.projection = v.extract::<PyProjection>().map_err(|e| arg(e.into()))?.into(),
            "core_fraction" => o.core_fraction = v.extract().map_err(arg)?,
            // Counts as errors::Int first: a negative one, or one beyond 64 bits, is a
            // ParameterError naming the option, not pyo3's OverflowError.
            "core_triangles" => o.core_triangles = errors::count(v.extract().map_err(arg)?, "core_triangles")?,
            "core_layers" => o.core_layers = errors::count(v.extract().map_err(arg)?, "core_layers")?,
            "spacing" => spacing = v.extract::<Option<f64>>().map_err(arg)?,
            "particles" => particles = Some(errors::count(v.extract().map_err(arg)?, "particles")?),
            "density" => o.density = v.extract().map_err(arg)?,
            "min_region_particles" => o.min_region_particles = errors::count(v.extract().map_err(arg)?, "min_region_particles")?,
            "field_voxels" => o.field_voxels = errors::count(v.extract().map_err(arg)?, "field_voxels")?,
            "homogenise" => o.homogenise = v.extract().map_err(arg)?,
            _ => return Err(errors::type_error(format!("unexpected keyword argument '{key}' (the build options are {})", OPTION_NAMES.join(", ")))),
        }
    }
    match (spacing, particles) {
        (Some(s), _) => o.spacing = Spacing::Length(s),
        (None, Some(n)) => o.spacing = Spacing::Count(n),
        (None, None) => {}
    }
    Ok(o)
}

/// The keyword arguments of the builders, in the order of the docs.
const OPTION_NAMES: [&str; 10] = [
    "projection",
    "core_fraction",
    "core_triangles",
    "core_layers",
    "spacing",
    "particles",
    "density",
    "min_region_particles",
    "field_voxels",
    "homogenise",
];

/// `HybridOptions::default()` as a dict keyed as the builders' keyword arguments (`spacing` None
/// with a particle count, `particles` None with a spacing).
pub fn default_options(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let o = HybridOptions::default();
    let d = PyDict::new(py);
    d.set_item("projection", PyProjection::from(o.projection))?;
    d.set_item("core_fraction", o.core_fraction)?;
    d.set_item("core_triangles", o.core_triangles)?;
    d.set_item("core_layers", o.core_layers)?;
    let (spacing, particles) = match o.spacing {
        Spacing::Length(s) => (Some(s), None),
        Spacing::Count(n) => (None, Some(n)),
    };
    d.set_item("spacing", spacing)?;
    d.set_item("particles", particles)?;
    d.set_item("density", o.density)?;
    d.set_item("min_region_particles", o.min_region_particles)?;
    d.set_item("field_voxels", o.field_voxels)?;
    d.set_item("homogenise", o.homogenise)?;
    debug_assert_eq!(d.len(), OPTION_NAMES.len());
    Ok(d)
}

fn build_wall(py: Python<'_>, wall: Wall, o: HybridOptions) -> PyResult<PyHybridModel> {
    let model = errors::guard("HybridModel.build", || py.detach(|| hybrid::build(&wall, &o)).map_err(hybrid_error))?;
    Ok(PyHybridModel { model })
}

#[pymethods]
impl PyHybridModel {
    /// Build from two nested closed surfaces (the wall lies inside ``outer``, outside ``inner``).
    ///
    /// Keyword-only options, each defaulting to the core's (``HybridOptions::default()``; the
    /// values are in ``palpate.defaults.hybrid``): ``projection`` (:class:`Projection`);
    /// ``core_fraction``: the fraction of the wall (transmural coordinate, from the inner
    /// surface) the FEM core takes; ``core_triangles``: triangles of the simplified inner
    /// surface (3 tets each per layer; 0: automatic, ``AUTO_CORE_TRIANGLES_CLOSED`` for a closed
    /// wall, ``AUTO_CORE_TRIANGLES_BASE`` for one with a base, raised while prisms would twist);
    /// ``core_layers``: prism layers of the core (0: automatic, the core's height over its
    /// triangles' edge, so that its tets are about as tall as wide); ``spacing`` [m] or, if None, about
    /// ``particles`` particles in the shell; ``density`` [kg/m^3]; ``min_region_particles``:
    /// activation regions grow by rings of outer triangles until they hold this many;
    /// ``field_voxels``: wall voxels of the transmural solve; ``homogenise``: compute the core's
    /// homogenised stiffness (default True, see ``HybridModel.homogenisation``). An unknown
    /// option is a TypeError.
    #[staticmethod]
    #[pyo3(signature = (inner, outer, **options))]
    fn build_nested(
        py: Python<'_>,
        #[pyo3(from_py_with = conv::arg)] inner: PyRef<'_, PyTriSurface>,
        #[pyo3(from_py_with = conv::arg)] outer: PyRef<'_, PyTriSurface>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyHybridModel> {
        let o = self::options(options)?;
        let wall = Wall::nested(&inner.inner, &outer.inner).map_err(hybrid_error)?;
        build_wall(py, wall, o)
    }

    /// Build from one closed surface ``points`` (n, 3) [m], ``triangles`` (m, 3) with a part per
    /// triangle, ``parts`` (m,) int: 0 inner, 1 outer, 2 base (a truncated ventricle). Same
    /// options as :meth:`build_nested`.
    #[staticmethod]
    #[pyo3(signature = (points, triangles, parts, **options))]
    fn build_tagged(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        parts: &Bound<'_, PyAny>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<PyHybridModel> {
        let o = self::options(options)?;
        let pts = conv::points(points, "points")?;
        let tris = conv::index_rows::<3>(triangles, "triangles")?;
        let raw = conv::codes(parts, "parts", "a 1-D integer array (0 inner, 1 outer, 2 base)")?;
        if raw.len() != tris.len() {
            return Err(crate::errors::param_error_from(format!("parts: {} entries for {} triangles", raw.len(), tris.len())));
        }
        let tags = raw
            .iter()
            .enumerate()
            .map(|(t, &p)| match p {
                0 => Ok(WallPart::Inner),
                1 => Ok(WallPart::Outer),
                2 => Ok(WallPart::Base),
                _ => Err(crate::errors::param_error_from(format!("parts: triangle {t} has part {p}; expected 0 (inner), 1 (outer) or 2 (base)"))),
            })
            .collect::<PyResult<Vec<_>>>()?;
        let (surface, _) = TriSurface::from_arrays(&pts, &tris).map_err(surface_error)?;
        let wall = Wall::tagged(surface, tags).map_err(hybrid_error)?;
        if wall.dropped_pieces > 0 {
            errors::warn(
                py,
                format!(
                    "dropped {} closed piece(s) of the surface enclosing less than {} of the largest (specks, e.g. left by a surface repair)",
                    wall.dropped_pieces,
                    palpate_core::hybrid::build::MIN_PIECE_VOLUME
                ),
            )?;
        }
        build_wall(py, wall, o)
    }

    /// Save to ``path`` (one versioned binary file with a checksum).
    fn save(&self, py: Python<'_>, #[pyo3(from_py_with = conv::arg)] path: std::path::PathBuf) -> PyResult<()> {
        py.detach(|| self.model.save(&path)).map_err(file_error)
    }

    /// Load a model saved with :meth:`save`. Raises :class:`ModelFileError` naming the file for
    /// a foreign, truncated, corrupted or other-version file.
    #[staticmethod]
    fn load(py: Python<'_>, #[pyo3(from_py_with = conv::arg)] path: std::path::PathBuf) -> PyResult<PyHybridModel> {
        let model = errors::guard(&format!("HybridModel.load({})", path.display()), || py.detach(|| HybridModel::load(&path)).map_err(file_error))?;
        Ok(PyHybridModel { model })
    }

    /// A model from the bytes of :meth:`to_bytes` (or of a file :meth:`save` wrote); how a
    /// model unpickles. Raises :class:`ModelFileError` as :meth:`load` does.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, #[pyo3(from_py_with = conv::arg)] data: Bound<'_, PyBytes>) -> PyResult<PyHybridModel> {
        let data = data.as_bytes();
        let model = errors::guard("HybridModel.from_bytes", || py.detach(|| hybrid::file::from_bytes(data, "<bytes>")).map_err(file_error))?;
        Ok(PyHybridModel { model })
    }

    /// The model file's bytes (what :meth:`save` writes).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, pyo3::types::PyBytes> {
        pyo3::types::PyBytes::new(py, &hybrid::file::to_bytes(&self.model))
    }

    /// FEM core node positions [m], (n, 3).
    #[getter]
    fn core_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.model.core_points)
    }
    /// FEM core tets, (m, 4) int64 (positive volume).
    #[getter]
    fn core_tets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.model.core_tets)
    }
    /// Outer boundary faces of the core (towards the shell), (f, 3) int64, oriented outward.
    #[getter]
    fn core_faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.model.core_faces)
    }
    /// Core nodes on a base (held fixed), int64 (k,); empty for a closed wall.
    #[getter]
    fn core_base_nodes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::usizes_to_py(py, &self.model.core_base_nodes)
    }
    /// The core's homogenised stiffness (``palpate_core::hybrid::homogenise``), as a dict:
    /// ``poisson`` (k,) and ``factor`` (k,) [-] (the factor by which ``HybridSim`` multiplies the
    /// core's Lame constants and viscosities, interpolated at the material's Poisson's ratio),
    /// ``spread`` (k, 2) (the smallest and largest factor over the probe loads), ``active`` (k,)
    /// [-] (the factor of the tissue's stiffness the core has under the active shell, where it
    /// stands for the wall's inner part only) and ``active_spread`` (k, 2), ``probes``,
    /// ``reference_tets`` (quadratic tets of the whole-wall reference), ``region_tets`` (of the
    /// inner part's), ``refinement`` (their triangles over the core's), ``load_radius`` [m],
    /// ``seconds`` (build time). Empty arrays: built with ``homogenise=False`` or by a palpate
    /// before it (model format 1); ``active`` empty in a model of format 2 (before 2026-12-08:
    /// the core under the active shell then has the tissue's stiffness).
    #[getter]
    fn homogenisation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let h = &self.model.homogenisation;
        let d = PyDict::new(py);
        d.set_item("poisson", PyArray1::from_slice(py, &h.poisson))?;
        d.set_item("factor", PyArray1::from_slice(py, &h.factor))?;
        let spread: Vec<f64> = h.spread.iter().flatten().copied().collect();
        d.set_item("spread", PyArray1::from_vec(py, spread).reshape([h.spread.len(), 2])?)?;
        d.set_item("active", PyArray1::from_slice(py, &h.active))?;
        let active_spread: Vec<f64> = h.active_spread.iter().flatten().copied().collect();
        d.set_item("active_spread", PyArray1::from_vec(py, active_spread).reshape([h.active_spread.len(), 2])?)?;
        d.set_item("probes", h.probes)?;
        d.set_item("reference_tets", h.reference_tets)?;
        d.set_item("region_tets", h.region_tets)?;
        d.set_item("refinement", h.refinement)?;
        d.set_item("load_radius", h.load_radius)?;
        d.set_item("seconds", h.seconds)?;
        Ok(d)
    }
    /// Particle rest positions [m], (p, 3), sorted by the outer triangle above them.
    #[getter]
    fn particles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.model.particles)
    }
    /// Particle masses [kg], (p,).
    #[getter]
    fn particle_masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        conv::f64s_to_py(py, &self.model.particle_mass)
    }
    /// Outer triangle above each particle, int64 (p,).
    #[getter]
    fn particle_outer_triangle<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::u32s_to_py(py, &self.model.particle_outer_tri)
    }
    /// Core face below each particle, int64 (p,).
    #[getter]
    fn particle_core_face<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::u32s_to_py(py, &self.model.particle_core_face)
    }
    /// Outer surface vertices [m], (s, 3): one activation region and one skin link each.
    #[getter]
    fn outer_points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.model.outer_points)
    }
    /// Outer surface triangles, (t, 3) int64.
    #[getter]
    fn outer_triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        conv::index_rows_to_py(py, &self.model.outer_tris)
    }
    /// Skin: the core face each outer vertex is tied to, int64 (s,).
    #[getter]
    fn skin_faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        conv::u32s_to_py(py, &self.model.skin_face)
    }
    /// Skin: barycentric coordinates on that face, (s, 3), each in [0, 1], rows summing to 1.
    #[getter]
    fn skin_barycentric<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::f64_rows_to_py(py, &self.model.skin_bary)
    }
    /// Skin: rest offset from the anchor point on the face to the vertex [m], (s, 3).
    #[getter]
    fn skin_offsets<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        conv::vec3s_to_py(py, &self.model.skin_offset)
    }
    /// Number of activation regions (outer vertices).
    #[getter]
    fn n_regions(&self) -> usize {
        self.model.n_regions()
    }
    /// Particle lattice spacing [m].
    #[getter]
    fn spacing(&self) -> f64 {
        self.model.spacing
    }
    /// Volume enclosed by the wall's boundary [m^3].
    #[getter]
    fn wall_volume(&self) -> f64 {
        self.model.wall_volume
    }
    /// Volume of the FEM core [m^3].
    #[getter]
    fn core_volume(&self) -> f64 {
        self.model.core_volume()
    }
    /// Volume the particles represent (lattice cells) [m^3].
    #[getter]
    fn shell_volume(&self) -> f64 {
        self.model.shell_volume()
    }

    /// RV(p_s): indices of the particles of region ``s``, int64.
    fn region_particles<'py>(&self, py: Python<'py>, s: errors::Int) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let s = self.check_region(s)?;
        let v: Vec<i64> = self.model.region_particle_ranges(s).into_iter().flat_map(|r| r.map(|i| i as i64)).collect();
        Ok(PyArray1::from_vec(py, v))
    }
    /// nv(p_s): the outer triangles of region ``s``, int64.
    fn region_triangles<'py>(&self, py: Python<'py>, s: errors::Int) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let s = self.check_region(s)?;
        Ok(conv::u32s_to_py(py, &self.model.region_triangles(s)))
    }
    /// The core faces under RV(p_s), int64.
    fn region_core_faces<'py>(&self, py: Python<'py>, s: errors::Int) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let s = self.check_region(s)?;
        Ok(conv::u32s_to_py(py, &self.model.region_core_faces(s)))
    }
    /// C(p_s): the projections on the core of nv(p_s)'s boundary vertices [m], (k, 3).
    fn region_curve<'py>(&self, py: Python<'py>, s: errors::Int) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let s = self.check_region(s)?;
        Ok(conv::vec3s_to_py(py, &self.model.region_curve(s)))
    }
    /// B(p_s): ``{"origin": (3,) [m], "h": voxel edge [m], "label": (nz, ny, nx) uint8 (0
    /// outside, 1 inside, 2 boundary), "gradient": (nz, ny, nx, 3) float32 unit vectors to the
    /// nearest interior voxel (zero inside)}``.
    fn region_field<'py>(&self, py: Python<'py>, s: errors::Int) -> PyResult<Bound<'py, PyDict>> {
        let s = self.check_region(s)?;
        let f = self.model.region_field(s);
        let [nx, ny, nz] = f.dims;
        let d = PyDict::new(py);
        d.set_item("origin", PyArray1::from_vec(py, vec![f.origin.x, f.origin.y, f.origin.z]))?;
        d.set_item("h", f.h)?;
        let labels: Vec<u8> = f
            .label
            .iter()
            .map(|l| match l {
                VoxelLabel::Outside => 0,
                VoxelLabel::Inside => 1,
                VoxelLabel::Boundary => 2,
            })
            .collect();
        d.set_item("label", PyArray1::from_vec(py, labels).reshape([nz, ny, nx])?)?;
        let g: Vec<f32> = f.gradient.iter().flatten().copied().collect();
        d.set_item("gradient", PyArray1::from_vec(py, g).reshape([nz, ny, nx, 3])?)?;
        Ok(d)
    }

    /// Counts, core quality, build statistics and memory, as a dict.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = &self.model;
        let d = PyDict::new(py);
        let sizes: Vec<usize> = (0..m.n_regions()).map(|s| m.region_len(s)).collect();
        let mut sorted = sizes.clone();
        sorted.sort_unstable();
        d.set_item(
            "projection",
            match m.options.projection {
                Projection::Transmural => "transmural",
                Projection::Radial => "radial",
            },
        )?;
        d.set_item("core_fraction", m.options.core_fraction)?;
        d.set_item("core_tets", m.core_tets.len())?;
        d.set_item("core_nodes", m.core_points.len())?;
        d.set_item("core_faces", m.core_faces.len())?;
        d.set_item("core_base_nodes", m.core_base_nodes.len())?;
        d.set_item("core_min_dihedral_deg", m.core_quality.min_dihedral_deg)?;
        d.set_item("core_volume_ratio", m.core_quality.min_volume / m.core_quality.max_volume)?;
        // The homogenisation at the default tissue's Poisson's ratio (0.4).
        let h = &m.homogenisation;
        d.set_item("homogenised", !h.is_empty())?;
        d.set_item("core_stiffening", h.factor(0.4))?;
        let [lo, hi] = h.poisson.iter().position(|&nu| nu == 0.4).map_or([1.0, 1.0], |k| h.spread[k]);
        d.set_item("core_stiffening_min", lo)?;
        d.set_item("core_stiffening_max", hi)?;
        d.set_item("core_active_stiffening", h.active_factor(0.4))?;
        let [lo, hi] = h.poisson.iter().position(|&nu| nu == 0.4).and_then(|k| h.active_spread.get(k).copied()).unwrap_or([1.0, 1.0]);
        d.set_item("core_active_stiffening_min", lo)?;
        d.set_item("core_active_stiffening_max", hi)?;
        d.set_item("homogenise_region_tets", h.region_tets)?;
        d.set_item("homogenise_reference_tets", h.reference_tets)?;
        d.set_item("build_homogenise_s", h.seconds)?;
        d.set_item("particles", m.particles.len())?;
        d.set_item("spacing_m", m.spacing)?;
        d.set_item("wall_volume_m3", m.wall_volume)?;
        d.set_item("core_volume_m3", m.core_volume())?;
        d.set_item("shell_volume_m3", m.shell_volume())?;
        d.set_item("outer_vertices", m.outer_points.len())?;
        d.set_item("outer_triangles", m.outer_tris.len())?;
        d.set_item("regions", m.n_regions())?;
        d.set_item("region_particles_min", sorted.first().copied().unwrap_or(0))?;
        d.set_item("region_particles_median", sorted.get(sorted.len() / 2).copied().unwrap_or(0))?;
        d.set_item("region_particles_max", sorted.last().copied().unwrap_or(0))?;
        d.set_item("voxels", m.grid.dims.iter().product::<usize>())?;
        d.set_item("voxel_m", m.grid.h)?;
        d.set_item("file_bytes", hybrid::file::to_bytes(m).len())?;
        let s = &m.stats;
        d.set_item("build_s", s.total_s)?;
        d.set_item("build_field_s", s.field_s)?;
        d.set_item("build_core_s", s.core_s)?;
        d.set_item("build_particles_s", s.particles_s)?;
        d.set_item("build_regions_s", s.regions_s)?;
        d.set_item("field_cg_iterations", s.field_iterations)?;
        d.set_item("fallback_particle_outer", s.fallback_particle_outer)?;
        d.set_item("fallback_particle_core", s.fallback_particle_core)?;
        d.set_item("fallback_skin", s.fallback_skin)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let m = &self.model;
        format!("HybridModel({} core tets, {} particles at {:.3} mm, {} regions)", m.core_tets.len(), m.particles.len(), m.spacing * 1e3, m.n_regions())
    }
}

impl PyHybridModel {
    /// The region index `s`: a negative one is a ParameterError, one past the end an
    /// ParameterIndexError (a ParameterError and an IndexError, as for a sequence).
    fn check_region(&self, s: errors::Int) -> PyResult<usize> {
        errors::index(s, self.model.n_regions(), "region", "regions")
    }
}
