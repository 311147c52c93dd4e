//! Typed errors. Bad input is reported once, at the boundary (mesh validation, material and model
//! compilation); the step loop assumes a valid model and reports only numerical failures.

use thiserror::Error;

/// A size that comes from input and exceeds the memory budget ([`crate::limits`]), refused before
/// the memory is taken. Names what was asked, how much, the budget and how to raise it.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{what}: {count:.3e} items need {need}, over the memory budget of {have} ({budget_source}); set the environment variable PALPATE_MAX_MEMORY to change it (e.g. PALPATE_MAX_MEMORY=32G) if the machine has the memory, or check the input", need = crate::limits::human_bytes(*.bytes), have = crate::limits::human_bytes(*.budget as f64))]
pub struct LimitError {
    /// What would have been allocated, e.g. "transmural voxel grid (312 x 905 x 1204 voxels)".
    pub what: String,
    /// How many items, and their bytes in all.
    pub count: f64,
    pub bytes: f64,
    /// The budget in bytes.
    pub budget: u64,
    /// Where the budget came from ([`crate::limits::Budget::source`]), e.g. "the cgroup's memory
    /// limit (2.0 GiB) x 0.5".
    pub budget_source: String,
}

/// A tetrahedral mesh that cannot be used. Every variant names the offending element or node.
/// `source` is the file the mesh came from when known (filled by the caller, e.g. the Python loader).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum MeshError {
    #[error("empty mesh: {what}")]
    Empty { what: &'static str },
    #[error("node {node}: non-finite coordinate ({x}, {y}, {z})")]
    NonFiniteNode { node: usize, x: f64, y: f64, z: f64 },
    #[error("tet {tet}: node index {index} out of range (mesh has {n_nodes} nodes)")]
    IndexOutOfRange { tet: usize, index: i64, n_nodes: usize },
    #[error("tet {tet}: node {node} appears twice")]
    RepeatedNode { tet: usize, node: usize },
    #[error("tet {tet}: degenerate (volume {volume:e} m^3, relative {relative:e} of its edge length cubed)")]
    Degenerate { tet: usize, volume: f64, relative: f64 },
    #[error("tet {tet}: duplicate of tet {other}")]
    DuplicateTet { tet: usize, other: usize },
    /// A tet on other node numbers at the same four corner positions as an earlier one (a mesh
    /// whose nodes were duplicated): its volume and mass would count twice.
    #[error("tet {tet}: duplicate of tet {other}: its nodes {nodes:?} lie at the corners of tet {other}'s nodes {other_nodes:?}, so that the volume and mass there would count twice")]
    CoincidentTet { tet: usize, other: usize, nodes: [usize; 4], other_nodes: [usize; 4] },
    #[error("node {node} is used by no tetrahedron")]
    UnusedNode { node: usize },
    #[error("cells of type '{cell_type}' are not tetrahedra (block {block})")]
    NotTetrahedral { cell_type: String, block: usize },
    #[error("{what}: expected shape {expected}, got {got}")]
    Shape { what: &'static str, expected: String, got: String },
    #[error("{file}: {source}")]
    InFile { file: String, source: Box<MeshError> },
    /// A generator's parameters whose mesh would fail validation, refused before it is built.
    #[error("{generator}: {reason}")]
    Generator { generator: &'static str, reason: String },
    #[error(transparent)]
    Limit(#[from] LimitError),
}

impl MeshError {
    /// Attach the file name the mesh came from.
    pub fn in_file(self, file: impl Into<String>) -> MeshError {
        MeshError::InFile { file: file.into(), source: Box::new(self) }
    }
}

/// A material whose parameters are not physical.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum MaterialError {
    #[error("{name} = {value} is not finite")]
    NonFinite { name: &'static str, value: f64 },
    #[error("{name} = {value} {unit} must be positive")]
    NotPositive { name: &'static str, value: f64, unit: &'static str },
    #[error("{name} = {value} {unit} must not be negative")]
    Negative { name: &'static str, value: f64, unit: &'static str },
    #[error("Poisson ratio nu = {0} must lie in (-1, 0.5) (0.5 is incompressible, which linear tetrahedra cannot represent)")]
    Poisson(f64),
    #[error("Lame parameters lambda = {lambda} Pa, mu = {mu} Pa give a non-positive bulk modulus")]
    Bulk { lambda: f64, mu: f64 },
    /// A solver that implements only some laws was given another (never silently replaced).
    #[error("{solver} supports the St. Venant-Kirchhoff law only for now, not {law}: give it a St. Venant-Kirchhoff material (the FEM body supports {law})")]
    UnsupportedLaw { law: crate::material::Law, solver: &'static str },
}

/// A model that cannot be compiled.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Material(#[from] MaterialError),
    #[error("fixed node {node} out of range (mesh has {n_nodes} nodes)")]
    FixedOutOfRange { node: usize, n_nodes: usize },
    #[error("gravity ({0}, {1}, {2}) m/s^2 is not finite")]
    Gravity(f64, f64, f64),
    #[error("integrator: {0}")]
    Integrator(String),
    #[error("particle {particle}: {reason}")]
    Particle { particle: usize, reason: String },
    #[error("{name} = {value}: {reason}")]
    Parameter { name: &'static str, value: f64, reason: &'static str },
    #[error("{0}")]
    Empty(&'static str),
    #[error(transparent)]
    Limit(#[from] LimitError),
}

/// A linear or nonlinear solve that failed.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SolveError {
    #[error("matrix not positive definite: pivot {pivot:e} at dof {dof} (node {node})")]
    NotPositiveDefinite { dof: usize, node: usize, pivot: f64 },
    #[error("Newton did not converge in {iterations} iterations (residual {residual:e} N, tolerance {tolerance:e} N)")]
    NoConvergence { iterations: usize, residual: f64, tolerance: f64 },
    #[error("non-finite value in {what} at node {node}")]
    NonFinite { what: &'static str, node: usize },
    #[error("{0}")]
    Invalid(String),
    /// The caller's interrupt (see [`crate::integrate::static_solve_with`]) asked the solve to
    /// stop; nothing of it is returned.
    #[error("interrupted after {iterations} Newton iterations")]
    Interrupted { iterations: usize },
}

/// A step that could not be completed. The state is left as it was before the step.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum StepError {
    #[error("time step dt = {0} s must be positive and finite")]
    BadTimeStep(f64),
    #[error("non-finite {what} at node {node} (t = {time} s): the state was restored to the start of the step")]
    NonFinite { what: &'static str, node: usize, time: f64 },
    /// A step whose state is still finite but past the physical speed bound
    /// ([`crate::divergence`]): the start of a divergence, contained as a non-finite step is.
    #[error("{what} at node {node} moves at {speed:.3e} m/s relative to the body, over the divergence bound of {bound:.3e} m/s (t = {time} s): the step is diverging (take a smaller dt, a stabler integrator, or check the material); the state was restored to the start of the step")]
    Diverging { what: &'static str, node: usize, speed: f64, bound: f64, time: f64 },
    #[error("state does not fit the model ({nodes} nodes): x has {x} rows, v {v}, f_ext {f_ext}")]
    StateShape { nodes: usize, x: usize, v: usize, f_ext: usize },
    #[error("workspace was made for {workspace} nodes, the model has {nodes}: make it with the model it steps")]
    WorkspaceShape { nodes: usize, workspace: usize },
    #[error("active particle index {index} out of range ({n} particles)")]
    ActiveOutOfRange { index: usize, n: usize },
    #[error("external force at node {node} is not finite")]
    NonFiniteForce { node: usize },
    #[error("the tool's position is not finite")]
    NonFiniteTool,
    /// A saved hybrid-simulation state that does not fit the simulation it is restored into
    /// (`runtime::SimState::restore`).
    #[error("the saved state does not fit this simulation: {0}")]
    Snapshot(String),
    /// A time step that needs more sub-steps than the cap (a dt far above the stable one, or a
    /// material so stiff that its stable step is tiny): refused instead of running for minutes.
    #[error("dt = {dt} s needs {substeps:.3e} sub-steps of the stable {stable_dt:e} s, over the cap of {cap} per step: take a smaller dt (or check the material's stiffness and the masses)")]
    TooManySubsteps { dt: f64, stable_dt: f64, substeps: f64, cap: usize },
    #[error(transparent)]
    Solve(#[from] SolveError),
}

/// A hybrid model that cannot be built from the given surfaces and options.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum HybridError {
    #[error(transparent)]
    Surface(#[from] crate::mesh::SurfaceError),
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error("{name} = {value}: {reason}")]
    Parameter { name: &'static str, value: f64, reason: &'static str },
    #[error("surface parts: {0}")]
    Parts(String),
    #[error("FEM core: {0}")]
    Core(String),
    /// A prism of the core stays twisted after its offsets are smoothed (the builder retries
    /// with more core triangles when they were chosen automatically).
    #[error("FEM core: prism {prism} (coarse inner triangle {triangle}) stays twisted after smoothing its offsets; try more core triangles or a smaller core fraction{}", radial_hint(.radial))]
    TwistedCore { prism: usize, triangle: usize, radial: bool },
    #[error("particles: {0}")]
    Particles(String),
    #[error(transparent)]
    Limit(#[from] LimitError),
}

fn radial_hint(radial: &bool) -> &'static str {
    match radial {
        true => "; the radial projection cannot serve this wall (it is not star-shaped about its mass centre): use the transmural projection",
        false => "",
    }
}

/// A compiled-model file that cannot be read.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelFileError {
    #[error("{path}: {reason}")]
    Io { path: String, reason: String },
    #[error("{path}: not a palpate model file (its first bytes are not the palpate magic number)")]
    NotAModel { path: String },
    #[error("{path}: model file format version {found}, this palpate reads versions 1 to {supported}; rebuild the model with `palpate build`")]
    Version { path: String, found: u32, supported: u32 },
    #[error("{path}: truncated: {field} needs {need} bytes at offset {offset}, the file has {have}")]
    Truncated { path: String, field: &'static str, offset: usize, need: usize, have: usize },
    #[error("{path}: corrupted: checksum {computed:016x} does not match the stored {stored:016x}")]
    Checksum { path: String, stored: u64, computed: u64 },
    #[error("{path}: corrupted: {reason}")]
    Corrupt { path: String, reason: String },
    /// A file whose sizes exceed the memory budget (a crafted count, or a genuinely huge model).
    #[error("{path}: {source}")]
    Limit { path: String, source: LimitError },
}

/// A probe load that cannot be applied to its body (`probe::ProbeLoad::new`).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum LoadError {
    #[error("at least one loaded node is needed")]
    NoNodes,
    #[error("loaded node {index}: index {node} out of range (body has {n_nodes} nodes)")]
    NodeOutOfRange { index: usize, node: usize, n_nodes: usize },
    #[error("the load's force is not finite")]
    NonFiniteForce,
    #[error("the load's force of {norm:e} N is over the bound of {max:e} N (crate::limits::MAX_FORCE_N)", max = crate::limits::MAX_FORCE_N)]
    ForceTooLarge { norm: f64 },
    #[error("ramp (start {start} s, duration {duration} s): both must be finite and the duration >= 0")]
    BadRamp { start: f64, duration: f64 },
}
