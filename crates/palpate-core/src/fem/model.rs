//! The immutable compiled model of a tetrahedral body.

use crate::error::{ModelError, SolveError};
use crate::fem::small_strain::Order;
use crate::fem::tet10::{self, Tet10Rest, TET10_EDGES};
use crate::fem::tet4::{self, TetRest};
use crate::integrate::{Filter, Integrator};
use crate::linalg::{ordering, BlockPattern, Ldl};
use crate::material::Material;
use crate::math::{is_finite3, Mat3, Vec3};
use crate::mesh::TetMesh;

pub(crate) const NONE: usize = usize::MAX;

/// Describes a body before compilation: mesh, material, boundary conditions, integrator.
#[derive(Debug, Clone)]
pub struct ModelBuilder {
    mesh: TetMesh,
    material: Material,
    fixed: Vec<usize>,
    gravity: Vec3,
    integrator: Integrator,
    attached: Vec<f64>,
    order: Order,
}

impl ModelBuilder {
    /// A body of `mesh` (positions in \[m\]) made of `material`; no fixed nodes, no gravity,
    /// the default integrator (quasi-Newton backward Euler).
    pub fn new(mesh: TetMesh, material: Material) -> ModelBuilder {
        ModelBuilder {
            mesh,
            material,
            fixed: Vec::new(),
            gravity: Vec3::zeros(),
            integrator: Integrator::default(),
            attached: Vec::new(),
            order: Order::Linear,
        }
    }
    /// The element order (default linear): [`Order::Quadratic`] makes each tet a 10-node element
    /// (`fem/tet10.rs`) whose edge nodes follow the mesh's vertices in the body's node arrays, one
    /// per edge in the order of [`Model::edges`], at the edges' midpoints at rest. Quadratic tets
    /// bend where linear ones lock (a wall one element across); each costs about ten linear ones.
    pub fn order(mut self, order: Order) -> Self {
        self.order = order;
        self
    }
    /// Nodes held at their rest position (indices into the body's nodes: with quadratic elements
    /// an edge node is held too when both its vertices are).
    pub fn fixed_nodes(mut self, nodes: Vec<usize>) -> Self {
        self.fixed = nodes;
        self
    }
    /// Gravitational acceleration \[m/s^2\], world frame (default zero).
    pub fn gravity(mut self, g: Vec3) -> Self {
        self.gravity = g;
        self
    }
    /// Masses \[kg\] `(n_nodes)` carried by the nodes besides the elements' own (e.g. a shell of
    /// particles tied to the body, in the hybrid model); empty: none.
    pub fn attached_masses(mut self, masses: Vec<f64>) -> Self {
        self.attached = masses;
        self
    }
    /// Time integrator used by [`crate::step`].
    pub fn integrator(mut self, i: Integrator) -> Self {
        self.integrator = i;
        self
    }

    /// Validate and precompute: rest shape inverses and volumes, lumped masses, the sparsity
    /// pattern over the free nodes, the rest Jacobians, a fill-reducing order and the symbolic
    /// factorisation used by the implicit integrators and the static solve.
    pub fn build(self) -> Result<Model, ModelError> {
        let ModelBuilder { mesh, material, fixed, gravity, integrator, attached, order } = self;
        if order == Order::Quadratic && matches!(integrator, Integrator::SemiImplicit { .. }) {
            return Err(ModelError::Parameter {
                name: "integrator",
                value: f64::NAN,
                reason:
                    "the paper's semi-implicit scheme is for linear tets (its per-node filter is not stable on quadratic ones): use a backward Euler integrator",
            });
        }
        let (rest_x, quadratic) = match order {
            Order::Linear => (mesh.points().to_vec(), None),
            Order::Quadratic => {
                let (x, q) = Quadratic::new(&mesh);
                (x, Some(q))
            }
        };
        let n = rest_x.len();
        if !is_finite3(&gravity) {
            return Err(ModelError::Gravity(gravity.x, gravity.y, gravity.z));
        }
        integrator.check().map_err(ModelError::Integrator)?;
        let mut is_fixed = vec![false; n];
        for &i in &fixed {
            if i >= n {
                return Err(ModelError::FixedOutOfRange { node: i, n_nodes: n });
            }
            is_fixed[i] = true;
        }
        if let Some(q) = &quadratic {
            let nv = mesh.n_nodes();
            for (k, [a, b]) in q.edges.iter().enumerate() {
                is_fixed[nv + k] |= is_fixed[*a] && is_fixed[*b];
            }
        }

        // Element rest data and lumped masses: each linear tet gives a quarter of rho V to each
        // node, a quadratic one its HRZ shares (`fem/tet10.rs`).
        let pts = &rest_x;
        let rest: Vec<TetRest> = if quadratic.is_some() {
            Vec::new()
        } else {
            mesh.tets().iter().map(|t| TetRest::new(&t.map(|i| pts[i]))).collect()
        };
        let mut mass = vec![0.0; n];
        for (t, r) in mesh.tets().iter().zip(&rest) {
            for &i in t {
                mass[i] += 0.25 * material.density() * r.volume;
            }
        }
        if let Some(q) = &quadratic {
            for (e, r) in q.elements.iter().zip(&q.rest) {
                let m = material.density() * r.volume();
                for (a, &i) in e.iter().enumerate() {
                    mass[i] += m * if a < 4 { tet10::VERTEX_MASS } else { tet10::EDGE_MASS };
                }
            }
        }
        if !attached.is_empty() {
            if attached.len() != n {
                return Err(ModelError::Parameter { name: "attached masses (count)", value: attached.len() as f64, reason: "one mass per node is needed" });
            }
            if let Some(i) = attached.iter().position(|m| !(*m >= 0.0 && m.is_finite())) {
                return Err(ModelError::Parameter { name: "attached mass", value: attached[i], reason: "must be finite and >= 0 (kg)" });
            }
            mass.iter_mut().zip(&attached).for_each(|(m, a)| *m += a);
        }

        // Free nodes and their adjacency (through shared tets).
        let mut node_to_free = vec![NONE; n];
        let mut free_nodes = Vec::new();
        for i in 0..n {
            if !is_fixed[i] {
                node_to_free[i] = free_nodes.len();
                free_nodes.push(i);
            }
        }
        let nf = free_nodes.len();
        let mut adj: Vec<Vec<usize>> = vec![Vec::new(); nf];
        let element_nodes: Box<dyn Iterator<Item = &[usize]>> = match &quadratic {
            None => Box::new(mesh.tets().iter().map(|t| &t[..])),
            Some(q) => Box::new(q.elements.iter().map(|e| &e[..])),
        };
        for t in element_nodes {
            for &a in t {
                for &b in t {
                    let (fa, fb) = (node_to_free[a], node_to_free[b]);
                    if fa != NONE && fb != NONE && fa != fb {
                        adj[fa].push(fb);
                    }
                }
            }
        }
        for a in adj.iter_mut() {
            a.sort_unstable();
            a.dedup();
        }
        let pattern = BlockPattern::from_adjacency(&adj);
        let mut quadratic = quadratic;
        if let Some(q) = quadratic.as_mut() {
            q.blocks = q.elements.iter().map(|e| element_blocks(e, &node_to_free, &pattern)).collect();
        }
        let tet_blocks: Vec<[usize; 16]> = rest.iter().zip(mesh.tets()).map(|(_, t)| element_blocks(t, &node_to_free, &pattern)).collect();
        // Rest Jacobians: K0 = df/dx and D0 = df/dv at rest, on the free pattern, and every
        // node's diagonal block (the paper's per-node J_F of eq. 34, "neighbours fixed").
        let mut k0 = vec![Mat3::zeros(); pattern.nnz()];
        let mut d0 = vec![Mat3::zeros(); pattern.nnz()];
        let mut node_k0 = vec![Mat3::zeros(); n];
        let mut node_d0 = vec![Mat3::zeros(); n];
        for ((t, r), blocks) in mesh.tets().iter().zip(&rest).zip(&tet_blocks) {
            let (k, d) = tet4::jacobians(&t.map(|i| pts[i]), r, &material);
            add_rest_jacobians(
                t,
                blocks,
                |a, c| k[a][c],
                d.as_ref().map(|d| move |a: usize, c: usize| d[a][c]),
                [&mut k0, &mut d0, &mut node_k0, &mut node_d0],
            );
        }
        if let Some(q) = &quadratic {
            for ((e, r), blocks) in q.elements.iter().zip(&q.rest).zip(&q.blocks) {
                let (k, d) = tet10::jacobians(&e.map(|i| pts[i]), r, &material);
                add_rest_jacobians(
                    e,
                    blocks,
                    |a, c| k[a][c],
                    d.as_ref().map(|d| move |a: usize, c: usize| d[a][c]),
                    [&mut k0, &mut d0, &mut node_k0, &mut node_d0],
                );
            }
        }

        // Fill-reducing order of the free nodes and the scalar upper-triangular pattern of the
        // permuted system, with the map from block entries to its values.
        let coords: Vec<Vec3> = free_nodes.iter().map(|&i| pts[i]).collect();
        let order = ordering::fill_reducing_order(&adj, &coords);
        let mut node_pos = vec![0usize; nf];
        for (k, &i) in order.iter().enumerate() {
            node_pos[i] = k;
        }
        let mut columns: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nf]; // (block row, pattern block)
        for i in 0..nf {
            for bi in pattern.row_ptr[i]..pattern.row_ptr[i + 1] {
                let (p, q) = (node_pos[i], node_pos[pattern.col[bi]]);
                if p <= q {
                    columns[q].push((p, bi));
                }
            }
        }
        let mut ap = Vec::with_capacity(nf + 1);
        let mut ai = Vec::new();
        let mut entry_to_a = vec![NONE; pattern.nnz()];
        ap.push(0);
        for col in columns.iter_mut() {
            col.sort_unstable();
            for &(p, bi) in col.iter() {
                entry_to_a[bi] = ai.len();
                ai.push(p);
            }
            ap.push(ai.len());
        }
        let ldl = Ldl::symbolic(nf, ap, ai);
        // A position x carries a round-off of eps |x|, hence a strain error of eps |x| |Dm^-1| and
        // an element force error of V (lambda + 2 mu) |Dm^-1|^2 eps |x| (the static solve's floor).
        let xmax = pts.iter().map(|p| p.norm()).fold(0.0, f64::max);
        let modulus = material.lambda() + 2.0 * material.mu();
        // (A quadratic tet: `sum_q w_q sum_a |g_qa|^2` for `V |Dm^-1|^2`.)
        let (position_noise2, tet_stiffness): (f64, Vec<f64>) = match &quadratic {
            None => (
                rest.iter().map(|r| (r.volume * modulus * r.dm_inv.norm_squared() * xmax).powi(2)).sum(),
                rest.iter().map(|r| 2.0 * r.volume * modulus * r.dm_inv.norm_squared()).collect(),
            ),
            Some(q) => (
                q.rest.iter().map(|r| (modulus * r.gradient_scale() * xmax).powi(2)).sum(),
                q.rest.iter().map(|r| 2.0 * modulus * r.gradient_scale()).collect(),
            ),
        };
        let mass_position2: f64 = (0..n).filter(|&i| !is_fixed[i]).map(|i| mass[i] * mass[i] * pts[i].norm_squared()).sum();
        let filter_alpha = match integrator {
            Integrator::SemiImplicit { filter: Filter::Stable } => crate::integrate::stable_filter_factor(&pattern, &k0, &d0, !material.is_undamped()),
            _ => 1.0,
        };

        Ok(Model {
            mesh,
            rest_x,
            quadratic,
            material,
            rest,
            mass,
            fixed: is_fixed,
            gravity,
            integrator,
            free_nodes,
            node_to_free,
            pattern,
            tet_blocks,
            k0,
            d0,
            node_k0,
            node_d0,
            node_pos,
            order,
            refresh_cost: crate::integrate::ITERATIONS_PER_FACTOR_RATIO * ldl.factor_to_solve_ratio(),
            update_cost: ldl.update_to_factor_ratio(),
            position_noise2,
            tet_stiffness,
            mass_position2,
            entry_to_a,
            ldl,
            filter_alpha,
        })
    }
}

/// A compiled, immutable tetrahedral body: rest geometry, element data, masses, material,
/// boundary conditions and the structures of the linear solver. Shareable between threads.
#[derive(Debug, Clone)]
pub struct Model {
    pub(crate) mesh: TetMesh,
    /// Every node's rest position \[m\]: the mesh's vertices, then (quadratic) the edge nodes.
    pub(crate) rest_x: Vec<Vec3>,
    /// The quadratic elements, or `None` for linear tets (then in `rest` and `tet_blocks`).
    pub(crate) quadratic: Option<Quadratic>,
    pub(crate) material: Material,
    pub(crate) rest: Vec<TetRest>,
    pub(crate) mass: Vec<f64>,
    pub(crate) fixed: Vec<bool>,
    pub(crate) gravity: Vec3,
    pub(crate) integrator: Integrator,
    pub(crate) free_nodes: Vec<usize>,
    /// Node -> its index among the free nodes, or NONE if fixed (inverse of `free_nodes`).
    pub(crate) node_to_free: Vec<usize>,
    /// Block pattern over the free nodes.
    pub(crate) pattern: BlockPattern,
    /// Per tet, the pattern block of node pair (a, c) at `4a + c`, or NONE if either is fixed.
    pub(crate) tet_blocks: Vec<[usize; 16]>,
    pub(crate) k0: Vec<Mat3>,
    pub(crate) d0: Vec<Mat3>,
    pub(crate) node_k0: Vec<Mat3>,
    pub(crate) node_d0: Vec<Mat3>,
    /// Free node -> position in the elimination order (its unknowns are 3 pos .. 3 pos + 2).
    pub(crate) node_pos: Vec<usize>,
    /// Position in the elimination order -> free node (inverse of `node_pos`).
    pub(crate) order: Vec<usize>,
    /// Pattern block -> index into the permuted upper block triangle of the system, or NONE
    /// (blocks below the diagonal after permutation, given by symmetry).
    pub(crate) entry_to_a: Vec<usize>,
    /// Symbolic factorisation (cloned into each workspace for the numeric factors).
    pub(crate) ldl: Ldl,
    /// Squared force error \[N^2\] (over eps^2) from the round-off of positions far from the origin,
    /// summed over elements: `(V (lambda + 2 mu) |Dm^-1|^2 |x|max)^2` (integrate/potential.rs).
    pub(crate) position_noise2: f64,
    /// Per tet, `2 V (lambda + 2 mu) |Dm^-1|^2` \[N/m\]: with its energy `W`, `2 W k` estimates the
    /// squared magnitude of its nodal forces (for the gradient's round-off level).
    pub(crate) tet_stiffness: Vec<f64>,
    /// `sum m_i^2 |X_i|^2` over the free nodes \[kg^2 m^2\]: over `h^4`, the squared round-off
    /// scale (over eps^2) of the incremental potential's inertial gradient.
    pub(crate) mass_position2: f64,
    /// A factorisation's cost in quasi-Newton iterations (when to refresh its initial Hessian).
    pub(crate) refresh_cost: f64,
    /// A rank update's cost in factorisations (when to remake the factor rather than update it).
    pub(crate) update_cost: f64,
    /// Factor of the semi-implicit filter blocks (1: the paper's; see `integrate::Filter`).
    pub(crate) filter_alpha: f64,
}

impl Model {
    /// The validated mesh (rest positions \[m\] of the vertices, and the tets' vertices).
    pub fn mesh(&self) -> &TetMesh {
        &self.mesh
    }
    /// Number of nodes: the mesh's vertices, and with quadratic elements one per edge after them.
    pub fn n_nodes(&self) -> usize {
        self.rest_x.len()
    }
    /// Rest positions \[m\] of every node `(n_nodes)`.
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest_x
    }
    /// The element order.
    pub fn order(&self) -> Order {
        if self.quadratic.is_some() {
            Order::Quadratic
        } else {
            Order::Linear
        }
    }
    /// With quadratic elements, the two vertices of each edge node `(n_nodes - n_vertices)`, in
    /// node order (edge node `k` is node `n_vertices + k`); empty for linear tets.
    pub fn edges(&self) -> &[[usize; 2]] {
        self.quadratic.as_ref().map_or(&[], |q| &q.edges[..])
    }
    /// Each element's nodes: a linear tet's four or a quadratic tet's ten (vertices, then the
    /// edge nodes in the order of [`TET10_EDGES`]).
    pub fn element_nodes(&self, e: usize) -> &[usize] {
        match &self.quadratic {
            None => &self.mesh.tets()[e],
            Some(q) => &q.elements[e],
        }
    }
    /// `true` when no node is fixed (linear momentum is then conserved).
    pub fn is_free_body(&self) -> bool {
        self.free_nodes.len() == self.n_nodes()
    }
    /// Number of tets.
    pub fn n_tets(&self) -> usize {
        self.mesh.n_tets()
    }
    /// The material.
    pub fn material(&self) -> &Material {
        &self.material
    }
    /// The integrator `step` uses.
    pub fn integrator(&self) -> Integrator {
        self.integrator
    }
    /// Lumped node masses \[kg\], `(n_nodes)`.
    pub fn masses(&self) -> &[f64] {
        &self.mass
    }
    /// `true` for fixed nodes, `(n_nodes)`.
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }
    /// Gravity \[m/s^2\].
    pub fn gravity(&self) -> Vec3 {
        self.gravity
    }
    /// Per-tet rest data.
    pub fn rest(&self) -> &[TetRest] {
        &self.rest
    }
    /// The paper's per-node Jacobian block `J_F` of eq. (34), `d f_i / d x_i` at rest \[N/m\].
    pub fn node_jacobians(&self) -> &[Mat3] {
        &self.node_k0
    }
    /// Number of unknowns of the implicit systems (3 per free node).
    pub fn n_dofs(&self) -> usize {
        3 * self.free_nodes.len()
    }
    /// The semi-implicit filter factor `alpha` (1 unless the integrator is
    /// `SemiImplicit { filter: Filter::Stable }`).
    pub fn filter_factor(&self) -> f64 {
        self.filter_alpha
    }
    /// Cost of a factorisation of the implicit system relative to one pair of triangular solves
    /// (a block-operation count; see `Ldl::factor_to_solve_ratio`).
    pub fn factor_to_solve_ratio(&self) -> f64 {
        self.ldl.factor_to_solve_ratio()
    }
    /// Off-diagonal 3x3 blocks of the sparse factor L.
    pub fn factor_blocks(&self) -> usize {
        self.ldl.nnz_l()
    }

    /// Total strain energy \[J\] at positions `x` `(n_nodes)` \[m\].
    pub fn strain_energy(&self, x: &[Vec3]) -> f64 {
        if let Some(q) = &self.quadratic {
            return q.elements.iter().zip(&q.rest).map(|(e, r)| tet10::strain_energy(&e.map(|i| x[i]), r, &self.material)).sum();
        }
        self.mesh.tets().iter().zip(&self.rest).map(|(t, r)| tet4::strain_energy(&t.map(|i| x[i]), r, &self.material)).sum()
    }

    /// Per-element fields of positions `x` `(n_nodes)` \[m\] for output (ParaView), each
    /// `(n_tets)`: see [`ElementFields`].
    pub fn element_fields(&self, x: &[Vec3]) -> ElementFields {
        let n = self.n_tets();
        let mut out = ElementFields { von_mises: Vec::with_capacity(n), energy_density: Vec::with_capacity(n), det_f: Vec::with_capacity(n) };
        for e in 0..n {
            // A quadratic tet reports the means over its quadrature points.
            let (f, p, psi) = match &self.quadratic {
                None => {
                    let (t, r) = (self.mesh.tets()[e], &self.rest[e]);
                    let xe = t.map(|i| x[i]);
                    let (p, psi) = tet4::elastic_stress(&xe, r, &self.material);
                    (tet4::deformation_gradient(&xe, r), p, psi)
                }
                Some(q) => {
                    let (p, psi, f) = tet10::mean_stress(&q.elements[e].map(|i| x[i]), &q.rest[e], &self.material);
                    (f, p, psi)
                }
            };
            let j = f.determinant();
            // Cauchy stress sigma = P F^T / J; an inverted element (J <= 0) reports the Kirchhoff
            // stress P F^T instead (finite, and flagged by det_f).
            let tau = p * f.transpose();
            let sigma = if j > 0.0 { tau / j } else { tau };
            out.von_mises.push(tet4::von_mises(&(0.5 * (sigma + sigma.transpose()))));
            out.energy_density.push(psi);
            out.det_f.push(j);
        }
        out
    }

    /// Kinetic energy \[J\] of velocities `v` `(n_nodes)` \[m/s\] with the lumped masses.
    pub fn kinetic_energy(&self, v: &[Vec3]) -> f64 {
        0.5 * v.iter().zip(&self.mass).map(|(v, m)| m * v.norm_squared()).sum::<f64>()
    }

    /// Total linear momentum \[kg m/s\].
    pub fn momentum(&self, v: &[Vec3]) -> Vec3 {
        v.iter().zip(&self.mass).map(|(v, m)| v * *m).sum()
    }

    /// Internal (elastic plus, with `v`, viscous) nodal forces \[N\] into `out` `(n_nodes)`, overwritten.
    pub fn internal_forces(&self, x: &[Vec3], v: Option<&[Vec3]>, out: &mut [Vec3]) {
        out.iter_mut().for_each(|f| *f = Vec3::zeros());
        let damped = !self.material.is_undamped();
        if let Some(q) = &self.quadratic {
            for (e, r) in q.elements.iter().zip(&q.rest) {
                let ve = v.filter(|_| damped).map(|v| e.map(|i| v[i]));
                let f = tet10::forces(&e.map(|i| x[i]), ve.as_ref(), r, &self.material);
                for a in 0..10 {
                    out[e[a]] += f[a];
                }
            }
            return;
        }
        for (t, r) in self.mesh.tets().iter().zip(&self.rest) {
            let xe = t.map(|i| x[i]);
            let ve = match v {
                Some(v) if damped => Some(t.map(|i| v[i])),
                _ => None,
            };
            let f = tet4::forces(&xe, ve.as_ref(), r, &self.material);
            for a in 0..4 {
                out[t[a]] += f[a];
            }
        }
    }

    /// Total applied force on each node \[N\]: `f_ext + m g` added to `out`.
    pub(crate) fn add_applied(&self, f_ext: &[Vec3], out: &mut [Vec3]) {
        for i in 0..out.len() {
            out[i] += f_ext[i] + self.mass[i] * self.gravity;
        }
    }

    /// Assemble the tangent Jacobians at `x` into `k` (and `d` if damped) on the free pattern.
    pub(crate) fn assemble_jacobians(&self, x: &[Vec3], k: &mut [Mat3], d: &mut [Mat3]) {
        k.iter_mut().for_each(|b| *b = Mat3::zeros());
        d.iter_mut().for_each(|b| *b = Mat3::zeros());
        if let Some(q) = &self.quadratic {
            for ((e, r), blocks) in q.elements.iter().zip(&q.rest).zip(&q.blocks) {
                let (ke, de) = tet10::jacobians(&e.map(|i| x[i]), r, &self.material);
                for (j, &bi) in blocks.iter().enumerate() {
                    if bi != NONE {
                        k[bi] += ke[j / 10][j % 10];
                        if let Some(de) = &de {
                            d[bi] += de[j / 10][j % 10];
                        }
                    }
                }
            }
            return;
        }
        for ((t, r), blocks) in self.mesh.tets().iter().zip(&self.rest).zip(&self.tet_blocks) {
            let (ke, de) = tet4::jacobians(&t.map(|i| x[i]), r, &self.material);
            for e in 0..16 {
                let bi = blocks[e];
                if bi != NONE {
                    k[bi] += ke[e / 4][e % 4];
                    if let Some(de) = &de {
                        d[bi] += de[e / 4][e % 4];
                    }
                }
            }
        }
    }

    /// Blocks of the permuted system matrix `cm M + cd D + ck K` into `a` (length `ldl.nnz_a()`).
    pub(crate) fn system_values(&self, cm: f64, cd: f64, ck: f64, k: &[Mat3], d: &[Mat3], a: &mut [Mat3]) {
        for i in 0..self.free_nodes.len() {
            for bi in self.pattern.row_ptr[i]..self.pattern.row_ptr[i + 1] {
                let p = self.entry_to_a[bi];
                if p == NONE {
                    continue;
                }
                let mut blk = ck * k[bi];
                if cd != 0.0 {
                    blk += cd * d[bi];
                }
                if bi == self.pattern.diag[i] {
                    blk += Mat3::from_diagonal_element(cm * self.mass[self.free_nodes[i]]);
                }
                a[p] = blk;
            }
        }
    }

    /// Factor the system blocks `a` into `ldl`, translating a failed pivot into a node.
    pub(crate) fn factor(&self, ldl: &mut Ldl, a: &[Mat3]) -> Result<(), SolveError> {
        ldl.factor(a)
            .map_err(|e| SolveError::NotPositiveDefinite { dof: 3 * e.column, node: self.free_nodes[self.order[e.column]], pivot: e.pivot })
    }

    /// Scatter per-node vectors of the free nodes into the permuted unknown vector `b`.
    pub(crate) fn gather_free(&self, per_node: &[Vec3], b: &mut [Vec3]) {
        for (fi, &node) in self.free_nodes.iter().enumerate() {
            b[self.node_pos[fi]] = per_node[node];
        }
    }
}

/// The quadratic elements of a body (`fem/tet10.rs`).
#[derive(Debug, Clone)]
pub(crate) struct Quadratic {
    /// Each element's ten nodes: its vertices, then its edge nodes in the order of [`TET10_EDGES`].
    pub(crate) elements: Vec<[usize; 10]>,
    pub(crate) rest: Vec<Tet10Rest>,
    /// Per element, the pattern block of node pair (a, c) at `10 a + c`, or NONE.
    pub(crate) blocks: Vec<[usize; 100]>,
    /// The two vertices of each edge node (node `n_vertices + k`), lower index first.
    pub(crate) edges: Vec<[usize; 2]>,
}

impl Quadratic {
    /// The straight quadratic elements of `mesh`: every node's rest position (the vertices, then
    /// the midpoints of [`TetMesh::edges`]) and the elements (blocks left empty).
    fn new(mesh: &TetMesh) -> (Vec<Vec3>, Quadratic) {
        let pts = mesh.points();
        let nv = pts.len();
        let edges = mesh.edges();
        let node_of: std::collections::HashMap<[usize; 2], usize> = edges.iter().enumerate().map(|(k, e)| (*e, nv + k)).collect();
        let mut x = pts.to_vec();
        x.extend(edges.iter().map(|[a, b]| (pts[*a] + pts[*b]) * 0.5));
        let mut elements = Vec::with_capacity(mesh.n_tets());
        let mut rest = Vec::with_capacity(mesh.n_tets());
        for t in mesh.tets() {
            let mut e = [0usize; 10];
            e[..4].copy_from_slice(t);
            for (k, [i, j]) in TET10_EDGES.iter().enumerate() {
                e[4 + k] = node_of[&[t[*i].min(t[*j]), t[*i].max(t[*j])]];
            }
            // A validated mesh's tets have positive volume, so their straight map is valid.
            rest.push(Tet10Rest::new(&e.map(|i| x[i])).expect("a positive tet's straight quadratic map is valid"));
            elements.push(e);
        }
        (x, Quadratic { elements, rest, blocks: Vec::new(), edges })
    }
}

/// Per element of nodes `e` (N of them), the pattern block of each node pair `(a, c)` at
/// `N a + c`, or NONE when either is fixed.
fn element_blocks<const N: usize, const NN: usize>(e: &[usize; N], node_to_free: &[usize], pattern: &BlockPattern) -> [usize; NN] {
    let mut b = [NONE; NN];
    for a in 0..N {
        for c in 0..N {
            let (fa, fc) = (node_to_free[e[a]], node_to_free[e[c]]);
            if fa != NONE && fc != NONE {
                b[N * a + c] = pattern.find(fa, fc).expect("pattern holds every element pair");
            }
        }
    }
    b
}

/// Adds one element's rest Jacobians (`k(a, c)`, and `d(a, c)` if damped) into the free
/// pattern's `k0`, `d0` and the nodes' diagonal blocks `node_k0`, `node_d0`.
fn add_rest_jacobians<const N: usize, const NN: usize>(
    e: &[usize; N],
    blocks: &[usize; NN],
    k: impl Fn(usize, usize) -> Mat3,
    d: Option<impl Fn(usize, usize) -> Mat3>,
    [k0, d0, node_k0, node_d0]: [&mut Vec<Mat3>; 4],
) {
    for a in 0..N {
        node_k0[e[a]] += k(a, a);
        if let Some(d) = &d {
            node_d0[e[a]] += d(a, a);
        }
        for c in 0..N {
            let bi = blocks[N * a + c];
            if bi != NONE {
                k0[bi] += k(a, c);
                if let Some(d) = &d {
                    d0[bi] += d(a, c);
                }
            }
        }
    }
}

/// Per-element output fields ([`Model::element_fields`]), each `(n_tets)`, of the elastic part
/// of the stress (the viscous stress is left out: it vanishes at rest and is not a material state).
#[derive(Debug, Clone, PartialEq)]
pub struct ElementFields {
    /// Von Mises equivalent of the Cauchy stress \[Pa\] (of the Kirchhoff stress where det F <= 0).
    pub von_mises: Vec<f64>,
    /// Strain energy density per rest volume \[J/m^3\] (sums, times the rest volumes, to
    /// [`Model::strain_energy`]).
    pub energy_density: Vec<f64>,
    /// det F \[-\]: the volume ratio; <= 0 marks an inverted element.
    pub det_f: Vec<f64>,
}
