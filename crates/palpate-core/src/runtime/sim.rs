//! The compiled hybrid simulation ([`Sim`]): everything the tick reads and never writes, built once
//! from a [`HybridModel`] and a [`Material`] (as [`crate::Model`] is for the FEM body).

use super::confinement::Confinement;
use super::coupling::Coupling;
use super::embed::Embedding;
use super::stability::Shell;
use super::state::SimState;
use super::tool::{AreaTool, ToolOptions};
use crate::error::ModelError;
use crate::fem::{Model, ModelBuilder};
use crate::hybrid::HybridModel;
use crate::material::Material;
use crate::math::Vec3;
use crate::mesh::TetMesh;
use crate::meshfree::{ParticleModel, ParticleModelBuilder};
use crate::spatial::csr::Buckets;
use crate::Integrator;

/// The haptic tick the capped coupling stiffness is chosen for \[s\] ([`SimOptions::implicit_exchange`]
/// false).
pub const TICK: f64 = 1e-3;

/// A duration \[s\] in ticks of `dt` \[s\], rounded (the caller checked both: finite, `dt`
/// positive, `seconds` non-negative); a duration past `u64::MAX` ticks is `u64::MAX` (`as`
/// saturates), and the counts it feeds add saturating.
pub(crate) fn ticks_in(seconds: f64, dt: f64) -> u64 {
    (seconds / dt).round() as u64
}

/// Options of [`Sim::new`]. Lengths in metres; `Default` gives the values documented per field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimOptions {
    /// Particle kernel support radius in lattice spacings (default 1.8, as the particle bench).
    pub support_spacings: f64,
    /// Active particles within this many lattice spacings of their core face at rest are tied
    /// to it by the coupling springs (default 1.5: the first lattice layer over the core).
    pub coupling_depth_spacings: f64,
    /// The core's integrator (default: the quasi-Newton backward Euler, stable at any press).
    pub integrator: Integrator,
    /// The tool (default: a 5 mm sphere, its penalty per unit of skin area `12 E* / min(R, 4 h)`, see
    /// [`super::tool`]).
    pub tool: ToolOptions,
    /// How long a region stays active after its last contact \[s\] (default 0.1 s, so a slide
    /// does not toggle particles every tick): `linger / dt` ticks, rounded, at a tick of `dt`.
    pub linger: f64,
    /// Regions within the tool's radius plus this \[m\] become active (default 1 mm: a region
    /// enters before the tool reaches it for slides up to 1 m/s at 1 kHz, above a hand's usual
    /// 0.5 m/s; a wider margin activates more particles: 5 mm doubled them on the ventricle).
    pub activation_margin: f64,
    /// Coupling springs; `None`: [`Coupling::for_tissue`] with the material's Young's modulus,
    /// the lattice spacing, the mean particle mass and half-critical damping.
    pub coupling: Option<Coupling>,
    /// Confinement wall stiffness \[N/m\] per particle; `None`: the tissue's between two lattice
    /// neighbours, `E * spacing` (a wall as soft as the coupling springs, whose stiffness the
    /// core's node masses cap, let particles drift a voxel out of their regions under a press).
    pub confinement_stiffness: Option<f64>,
    /// The simulated tool's top speed \[m/s\] (default 0.5 m/s, above a hand's usual palpation):
    /// in a tick of `dt` it moves at most `max_tool_speed * dt` toward the device's position. A
    /// device that jumps (a dropped packet, a stall and a resume, a jab) is followed over several
    /// ticks by the simulated tool, whose force the device renders: the shell's explicit
    /// sub-steps cannot take a sphere appearing millimetres deep in one tick. A speed, not a
    /// step a tick, so that a physics ticking at 250 Hz follows the same hand as one at 1 kHz
    /// (a step of 0.5 mm a tick dragged a hand sliding faster than 0.125 m/s there).
    pub max_tool_speed: f64,
    /// The most particle sub-steps a tick takes (default 64; [`super::stability`] sets the count
    /// from the shell's stretch and springs, ~12 at rest on the ventricle: a tick that needs more
    /// runs late rather than diverge).
    pub max_substeps: usize,
    /// Selective mass scaling of the shell (default `Some(0.95)`; `None`: off): the particles whose
    /// Gershgorin stiffness rate is above this quantile of all of them get the mass that brings
    /// them down to it (`crate::meshfree` `mass_scaling.rs`). A lattice's poorly supported
    /// particles set the explicit shell's step; measured on the Rodero ventricle, 0.93% of added
    /// mass (on 5% of the particles, at most 3.2x one's own) takes the damped rest sub-step count
    /// of a 1 ms tick from 16 to 9, on the paper's ellipsoids 1.3% from 20 to 14; the synthetic
    /// ventricle's regular lattice has nothing to gain (18 either way), and its masses stay physical
    /// (`MassScaling::applied`). Statics are unchanged; the
    /// core carries the shell's physical mass.
    pub mass_scaling: Option<f64>,
    /// What a failed shell step does (diverging past the speed bound of [`crate::divergence`],
    /// or non-finite). `Some(pause)` \[s\] (default `Some(0.1)`): the tick goes on without
    /// the shell (every particle back at its tie, the tool meeting the skin and the core) and the
    /// shell stays off for `pause` (rounded to ticks) and until the tool has let go of the organ (no contact)
    /// before regions may enter again ([`super::TickReport`]'s `shell_failed`, `shell_off`); the
    /// hand keeps feeling the organ: the skin the particles carried fades back to its ties over
    /// [`super::skin::SHED_FADE`] (or the pause, if shorter), and the tool meets the core
    /// inside its implicit step ([`super::core_contact`]). `None`: the tick fails
    /// with the error, the state as it was (studies of the shell's own stability).
    pub shell_fallback: Option<f64>,
    /// The tool's penalty stiffness against the core's surface \[N/m\] (default
    /// [`super::core_contact::CORE_CONTACT_STIFFNESS`], 2000 N/m): taken inside the core's implicit
    /// step, at the surface's point nearest the tool's centre, so that a hard press cannot pass
    /// the tool through the coarse core ([`super::core_contact`]).
    pub core_contact_stiffness: f64,
    /// Hold the core (default true: at its base, or, for a closed wall, at its lowest nodes);
    /// false leaves the organ free (momentum studies).
    pub hold: bool,
    /// Stiffen the core by the model's homogenisation factor at the material's Poisson's ratio
    /// (default true; [`crate::hybrid::homogenise`]): the core's Lame constants and viscosities
    /// times [`HybridModel::homogenisation`]'s factor, the shell's the tissue's. False (or a model
    /// built without it): the paper's core, stiff as the tissue, which renders the wall 23-28% too
    /// soft under a large tool on the paper's ellipsoids (VALIDATION.md).
    pub homogenise: bool,
    /// The shell's coupling springs at the tissue's stiffness `E h`, their reactions taken by the
    /// core with their implicit share (`runtime/exchange.rs`; the springs held in the core's
    /// factor, so its step still takes one iteration): the force proportional to E and Hertz's
    /// `sqrt(R)` on a thick slab (VALIDATION.md). Default true. False: the springs capped by the
    /// explicit exchange's stability (`k sum_p w_p <= m / (2 dt^2)` on every core node at the 1 ms
    /// tick: 2.9 N/m on Rodero against `E h` = 49), which makes the force grow 1.7x, not 2x, with
    /// twice E and the wall 10-23% too soft on the slab; about 5-8% cheaper a tick (fewer
    /// particle sub-steps: BENCHMARKS.md). Kept for comparison.
    pub implicit_exchange: bool,
}

impl SimOptions {
    /// Every option in its range, or [`ModelError::Parameter`] naming the first that is not (with
    /// its unit and the range): what [`Sim::new`] checks before it builds anything, and what a
    /// binding or a loop description calls to refuse a bad option early. The tick then assumes
    /// them valid.
    pub fn check(&self) -> Result<(), ModelError> {
        let bad = |name, value, reason| Err(ModelError::Parameter { name, value, reason });
        let positive = |name, value: f64| {
            if value > 0.0 && value.is_finite() {
                Ok(())
            } else {
                bad(name, value, "must be positive and finite")
            }
        };
        let non_negative = |name, value: f64| {
            if value >= 0.0 && value.is_finite() {
                Ok(())
            } else {
                bad(name, value, "must be non-negative and finite")
            }
        };
        positive("support_spacings [lattice spacings]", self.support_spacings)?;
        non_negative("coupling_depth_spacings [lattice spacings]", self.coupling_depth_spacings)?;
        positive("tool_radius [m]", self.tool.radius)?;
        if let Some(k) = self.tool.area_stiffness {
            positive("tool_area_stiffness [N/m^3]", k)?;
        }
        non_negative("tool_area_damping [N s/m^3]", self.tool.area_damping)?;
        non_negative("linger [s]", self.linger)?;
        non_negative("activation_margin [m]", self.activation_margin)?;
        if let Some(c) = self.coupling {
            non_negative("coupling stiffness [N/m]", c.stiffness)?;
            non_negative("coupling damping [N s/m]", c.damping)?;
        }
        if let Some(k) = self.confinement_stiffness {
            non_negative("confinement_stiffness [N/m]", k)?;
        }
        positive("max_tool_speed [m/s]", self.max_tool_speed)?;
        if self.max_substeps == 0 {
            return bad("max_substeps", 0.0, "must be at least 1");
        }
        if let Some(q) = self.mass_scaling {
            if !(q > 0.0 && q <= 1.0) {
                return bad("mass_scaling quantile", q, "must be in (0, 1]");
            }
        }
        if let Some(pause) = self.shell_fallback {
            non_negative("shell_pause (shell_fallback) [s]", pause)?;
        }
        positive("core_contact_stiffness [N/m]", self.core_contact_stiffness)?;
        Ok(())
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            support_spacings: 1.8,
            coupling_depth_spacings: 1.5,
            integrator: Integrator::quasi_newton(),
            tool: ToolOptions::default(),
            linger: 0.1,
            activation_margin: 1e-3,
            coupling: None,
            confinement_stiffness: None,
            max_tool_speed: 0.5,
            max_substeps: 64,
            mass_scaling: Some(0.95),
            shell_fallback: Some(0.1),
            core_contact_stiffness: super::core_contact::CORE_CONTACT_STIFFNESS,
            hold: true,
            homogenise: true,
            implicit_exchange: true,
        }
    }
}

/// The compiled hybrid simulation: the FEM core body, a particle body over every shell particle,
/// the ties of the particles and of the skin to the core faces, and the model it came from.
#[derive(Debug, Clone)]
pub struct Sim {
    /// The hybrid model (regions, voxels, surfaces).
    pub hybrid: HybridModel,
    /// The FEM core (Omega_e): base nodes fixed (or, for a closed wall, see [`Sim::new`]).
    pub core: Model,
    /// The particle shell (Omega_p), every particle; a tick steps only the active ones.
    pub particles: ParticleModel,
    /// Each particle tied to its core face: where an inactive particle is.
    pub particle_tie: Embedding,
    /// Each outer vertex tied to its core face (the skin, §4).
    pub skin: Embedding,
    /// Particles tied to the core by a coupling spring while active.
    pub coupled: Vec<bool>,
    /// The coupling springs and the confinement wall, resolved from the options.
    pub coupling: Coupling,
    pub confinement: Confinement,
    /// The shell's stability data (the sub-step count of a tick, see [`super::stability`]).
    pub shell: Shell,
    /// The core's nodes on its outer faces (where the tool meets the core once it has pushed
    /// the shell aside).
    pub core_surface: Vec<usize>,
    /// Per core face, the largest `sum |w|` and offset \[m\] of the skin vertices tied to it
    /// ([`super::embed::Embedding::face_reach`]): how far the skin can have moved, from how far
    /// the core's faces moved (the tick's bound on its stale skin vertices).
    pub skin_face_reach: Vec<(f64, f64)>,
    /// The shell's mass carried by each core node \[kg\] `(n_core_nodes)` (in `core`'s masses).
    pub shell_mass: Vec<f64>,
    /// The skin's carriers: per outer vertex `v`, `skin_carriers.get(v)` are the outer triangles
    /// whose particles carry it over an active zone ([`SkinCarriers`]).
    pub skin_carriers: SkinCarriers,
    pub options: SimOptions,
    /// The tool, its penalty per unit area resolved for the material ([`ToolOptions::resolve`]).
    pub tool: AreaTool,
    /// The rest area each outer (skin) vertex carries in the tool's contact \[m^2\]: a third of
    /// its outer triangles' areas (the skin's total area, shared by its vertices), at most
    /// [`SKIN_AREA_CAP_SPACINGS2`] squared lattice spacings.
    pub skin_area: Vec<f64>,
    /// The factor the core's material is stiffened by (1: not homogenised; see
    /// [`SimOptions::homogenise`] and `runtime/homogenised_core.rs`).
    pub stiffening: f64,
    /// The factor of the tissue's stiffness the core tets under the active shell are brought to
    /// (the build's active factor, [`crate::hybrid::Homogenisation::active_factor`]; 1: the
    /// tissue's, without one).
    pub active_stiffening: f64,
    /// Per core node, its tets (where the core is brought to the build's active factor under
    /// the active shell).
    pub node_tets: Buckets,
}

/// Which particles carry each skin vertex over an active zone (§6.1: "in the active zone it
/// follows the particles under it"): those under its own triangles, or, where none of its
/// triangles has a particle under it, under the triangles of the next ring, then of the ring
/// after (up to [`SkinCarriers::MAX_RINGS`]).
///
/// Why the further rings: the build groups each particle under the outer triangle above it, and
/// a skin finer than the particle lattice leaves most triangles without one. On the Rodero
/// ventricle (63,260 triangles over 28,039 particles) 79% of the triangles have none and 27.6% of
/// the vertices have none under any of their own triangles (the ellipsoids 0%, the synthetic
/// ventricle 2.1%): those vertices stayed at their ties to the core over an active zone, so the
/// tool pressed the coarse core directly there while the particles under the patch went
/// untouched by them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SkinCarriers {
    /// Per outer vertex, its carrier triangles.
    pub tris: Buckets,
    /// The most `(particle, weight)` items all vertices together can give (the tick's buffer).
    pub max_items: usize,
}

impl SkinCarriers {
    /// Rings searched around a vertex for triangles with particles.
    pub const MAX_RINGS: usize = 3;

    /// The carriers of every outer vertex of `h`.
    pub fn new(h: &HybridModel) -> SkinCarriers {
        let n = h.outer_points.len();
        let adj = &h.outer_adjacency.vertex_tris;
        // (A damaged table, which a model file's check refuses, counts as no particle.)
        let ptr = &h.tri_particle_ptr;
        let count = |t: usize| match (ptr.get(t), ptr.get(t + 1)) {
            (Some(&a), Some(&b)) => b.saturating_sub(a) as usize,
            _ => 0,
        };
        let (mut offsets, mut tris, mut max_items) = (Vec::with_capacity(n + 1), Vec::new(), 0);
        offsets.push(0u32);
        let (mut seen, mut ring, mut next, mut all) = (vec![false; h.outer_tris.len()], Vec::new(), Vec::new(), Vec::new());
        for v in 0..n {
            ring.clear();
            ring.extend(adj.get(v).iter().map(|&t| t as usize));
            ring.iter().for_each(|&t| seen[t] = true);
            all.clear();
            all.extend_from_slice(&ring);
            for _ in 0..Self::MAX_RINGS {
                let start = tris.len();
                tris.extend(ring.iter().filter(|&&t| count(t) > 0).map(|&t| t as u32));
                if tris.len() > start {
                    max_items += tris[start..].iter().map(|&t| count(t as usize)).sum::<usize>();
                    break;
                }
                next.clear();
                for &t in &ring {
                    for &u in &h.outer_tris[t] {
                        for &t2 in adj.get(u) {
                            if !seen[t2 as usize] {
                                seen[t2 as usize] = true;
                                next.push(t2 as usize);
                            }
                        }
                    }
                }
                all.extend_from_slice(&next);
                std::mem::swap(&mut ring, &mut next);
            }
            all.iter().for_each(|&t| seen[t] = false);
            offsets.push(tris.len() as u32);
        }
        SkinCarriers { tris: Buckets { ptr: offsets, items: tris }, max_items }
    }

    /// The carrier triangles of outer vertex `v`.
    #[inline]
    pub fn get(&self, v: usize) -> &[u32] {
        self.tris.get(v)
    }
}

impl Sim {
    /// Compiles `hybrid` with `material` (the same law and constants in the core and the shell).
    /// The core is held at its base nodes; a closed wall (no base) is held at its core nodes
    /// within 30% of the core's height from its lowest point, so that a press cannot push the
    /// organ away.
    pub fn new(hybrid: HybridModel, material: Material, options: SimOptions) -> Result<Sim, ModelError> {
        options.check()?;
        let tool = options.tool.resolve(&material, hybrid.spacing);
        if !(tool.stiffness > 0.0 && tool.stiffness.is_finite()) {
            // The default of a material with a nonsense modulus (the material's own check refuses it).
            return Err(ModelError::Parameter { name: "tool area stiffness [N/m^3]", value: tool.stiffness, reason: "must be positive and finite" });
        }
        let skin_area = skin_areas(&hybrid.outer_points, &hybrid.outer_tris, SKIN_AREA_CAP_SPACINGS2 * hybrid.spacing * hybrid.spacing);
        let pts: Vec<[f64; 3]> = hybrid.core_points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tets: Vec<[i64; 4]> = hybrid.core_tets.iter().map(|t| t.map(|i| i as i64)).collect();
        let (mesh, _) = TetMesh::from_arrays(&pts, &tets)?;
        let fixed = if !options.hold {
            vec![]
        } else if hybrid.core_base_nodes.is_empty() {
            lowest_nodes(&hybrid.core_points, crate::hybrid::homogenise::CLOSED_HOLD_FRACTION)
        } else {
            hybrid.core_base_nodes.clone()
        };
        let h = hybrid.spacing;
        let particle_tie = Embedding::project(&hybrid.core_points, &hybrid.core_faces, &hybrid.particle_core_face, &hybrid.particles);
        // The shell rides on the core where it is not simulated: its mass belongs to the core's
        // inertia (spread by the ties' weights). The few active particles then count twice (a
        // few percent of the shell), which the momentum bookkeeping does not mind: each body's
        // momentum changes by the impulses it receives.
        let mut attached = vec![0.0; hybrid.core_points.len()];
        for (p, &m) in hybrid.particle_mass.iter().enumerate() {
            particle_tie.spread_scalar(p, m, &mut attached);
        }
        // The core stands for the whole wall where no particle is active: its material is the
        // tissue's, stiffened by the build's homogenisation (`crate::hybrid::homogenise`).
        let stiffening = if options.homogenise { hybrid.homogenisation.factor(material.poisson()) } else { 1.0 };
        // Under the active shell it stands for the wall's inner part only (the build's active
        // factor; 1, the tissue's, for a model without one).
        let active_stiffening = if options.homogenise { hybrid.homogenisation.active_factor(material.poisson()) } else { 1.0 };
        let core_material = material.stiffened(stiffening)?;
        let core = ModelBuilder::new(mesh, core_material)
            .fixed_nodes(fixed)
            .integrator(options.integrator)
            .attached_masses(attached.clone())
            .build()?;
        // A lattice leaves a few lone particles in thin parts of a shell (a base's rim); they are held
        // (and, active, carried to the core by the ring) rather than refusing the model.
        let mut builder =
            ParticleModelBuilder::new(hybrid.particles.clone(), hybrid.particle_mass.clone(), material, options.support_spacings * h).fix_unsupported(true);
        if let Some(q) = options.mass_scaling {
            builder = builder.mass_scaling(q);
        }
        let particles = builder.build()?;
        let skin = Embedding::from_parts(&hybrid.core_points, &hybrid.core_faces, &hybrid.skin_face, &hybrid.skin_bary, &hybrid.skin_offset);
        let depth = options.coupling_depth_spacings * h;
        let coupled: Vec<bool> = particle_tie.offsets().iter().zip(particles.fixed()).map(|(o, &held)| o.norm() <= depth && !held).collect();
        let mean_mass = hybrid.particle_mass.iter().sum::<f64>() / hybrid.particle_mass.len().max(1) as f64;
        let coupling = options.coupling.unwrap_or_else(|| tissue_coupling(&options, &material, h, mean_mass, &core, &coupled, &particle_tie));
        let confinement = Confinement::new(options.confinement_stiffness.unwrap_or(material.young() * h));
        let shell = Shell::new(&particles, &coupled, &coupling, &confinement);
        let mut core_surface: Vec<usize> = hybrid.core_faces.iter().flatten().copied().collect();
        core_surface.sort_unstable();
        core_surface.dedup();
        let skin_face_reach = skin.face_reach(hybrid.core_faces.len());
        let skin_carriers = SkinCarriers::new(&hybrid);
        let node_tets = Buckets::build(core.n_nodes(), core.n_tets(), |t| core.mesh().tets()[t]);
        Ok(Sim {
            hybrid,
            core,
            particles,
            particle_tie,
            skin,
            skin_face_reach,
            coupled,
            coupling,
            confinement,
            shell,
            core_surface,
            shell_mass: attached,
            skin_carriers,
            options,
            tool,
            skin_area,
            stiffening,
            active_stiffening,
            node_tets,
        })
    }

    /// The factor the core's material was stiffened by (1: not homogenised; see
    /// [`SimOptions::homogenise`]).
    pub fn core_stiffening(&self) -> f64 {
        self.stiffening
    }

    /// The factor of the tissue's stiffness the core has under the active shell (1 when not
    /// homogenised or built before the active factor; see `runtime/homogenised_core.rs`).
    pub fn active_core_stiffening(&self) -> f64 {
        self.active_stiffening
    }

    /// The tissue's material, as given to [`Sim::new`] (the shell's; the core's is it stiffened
    /// by [`Sim::core_stiffening`]).
    pub fn material(&self) -> &Material {
        self.particles.material()
    }

    /// Number of shell particles.
    pub fn n_particles(&self) -> usize {
        self.hybrid.particles.len()
    }

    /// The whole skin \[m\] into `out` `(n_outer)`, fresh: over active triangles carried by the
    /// particles under it, elsewhere at its ties to the core (`SimState::skin` is fresh only near
    /// the tool, and elsewhere within [`super::tick::SKIN_LIVE_MARGIN`] of this).
    pub fn skin_positions(&self, state: &SimState, out: &mut [Vec3]) {
        let x = &state.core.x;
        for (i, o) in out.iter_mut().enumerate() {
            let carried = if super::skin::over_active(self, &state.activation, i) {
                super::skin::over_particles(self, &state.activation, i, &state.particles.x, x, None)
            } else {
                None
            };
            *o = carried.unwrap_or_else(|| self.skin.position(i, x));
        }
    }

    /// Every particle's position \[m\] into `out` `(n_particles)`: the active ones as simulated,
    /// the others at their ties to the core (where they are drawn).
    pub fn particle_positions(&self, state: &SimState, out: &mut [Vec3]) {
        for (p, o) in out.iter_mut().enumerate() {
            *o = if state.is_active[p] { state.particles.x[p] } else { self.particle_tie.position(p, &state.core.x) };
        }
    }
}

/// Nodes within `fraction` of the height above the lowest point.
fn lowest_nodes(points: &[Vec3], fraction: f64) -> Vec<usize> {
    let cut = crate::hybrid::homogenise::held_cut(points, fraction);
    (0..points.len()).filter(|&i| points[i].z <= cut).collect()
}

/// The most skin area one vertex carries in the tool's contact, in squared lattice spacings
/// ([`Sim::skin_area`]).
///
/// Why a cap: a skin much coarser than the particle lattice puts a whole triangle fan's penalty
/// on one vertex, carried by the few particles under it. Uncapped, on a 66-vertex ellipsoid skin
/// (230 mm^2 a vertex, 4 mm lattice) the 4 mm sphere met one vertex with 25 kN/m: the vertex and
/// its particles bounced off the tool, the force 1.7 N one tick and 0 the next three. Capped, such
/// a skin's contact is softer per area than asked (the tool sinks between its vertices anyway).
/// Rodero's skin (0.72 mm^2 a vertex on a 1.6 mm lattice) is not capped, the ellipsoids' (median
/// 2.8 mm^2, cap 3.3 mm^2 on 1.15 mm) only at its largest vertices; the tests' synthetic
/// ventricle (median 2.7 mm^2 on 0.90 mm) mostly, at 2.0 mm^2 (172 N/m a vertex with the 5 mm
/// tool, 2.9x the per-point 60 N/m of before). Why 2.5: it holds every hybrid test, the coarse
/// 66-vertex model's included (2026-12-07); no bounce was seen up to it, and an uncapped vertex
/// of 14 squared spacings bounced. A damping near critical for the mass a vertex carries
/// (`1 / sum(w_p^2 / m_p)`) would let coarse skins be as stiff as fine ones: not yet tried.
pub const SKIN_AREA_CAP_SPACINGS2: f64 = 2.5;

/// The coupling springs' default (`SimOptions::coupling` not given): the tissue's
/// ([`Coupling::for_tissue`] at lattice spacing `h` \[m\] and mean particle mass \[kg\]), capped by
/// the explicit exchange's stability when the core takes the reactions once a tick
/// (`implicit_exchange` off).
fn tissue_coupling(options: &SimOptions, material: &Material, h: f64, mean_mass: f64, core: &Model, coupled: &[bool], particle_tie: &Embedding) -> Coupling {
    let c = Coupling::for_tissue(material.young(), h, mean_mass, 0.5);
    if options.implicit_exchange {
        // As stiff as the tissue: the core takes the reactions with their implicit share
        // (super::exchange), stable at any stiffness up to its time.
        return c;
    }
    // The core takes the springs' reactions explicitly, once a tick: the springs on a
    // core node, `k sum_p w_p`, must stay below its mass over dt^2 (half of it, at the
    // 1 ms haptic tick) or the exchange diverges; within that, as stiff as the tissue.
    let mut weight = vec![0.0; core.n_nodes()];
    for p in (0..coupled.len()).filter(|&p| coupled[p]) {
        particle_tie.spread_scalar(p, 1.0, &mut weight);
    }
    let limit = (0..core.n_nodes())
        .filter(|&a| weight[a] > 0.0 && !core.fixed()[a])
        .map(|a| 0.5 * core.masses()[a] / (TICK * TICK * weight[a]))
        .fold(f64::INFINITY, f64::min);
    if c.stiffness > limit {
        Coupling::for_tissue(limit / h, h, mean_mass, 0.5)
    } else {
        c
    }
}

/// A third of each vertex's triangles' areas \[m^2\] `(n_points)`, at most `cap`.
fn skin_areas(points: &[Vec3], tris: &[[usize; 3]], cap: f64) -> Vec<f64> {
    let mut area = vec![0.0; points.len()];
    for t in tris {
        let a = 0.5 * (points[t[1]] - points[t[0]]).cross(&(points[t[2]] - points[t[0]])).norm() / 3.0;
        t.iter().for_each(|&v| area[v] += a);
    }
    area.iter_mut().for_each(|a| *a = a.min(cap));
    area
}
