//! The skin: the outer surface the tool meets and the user sees, tied to the core's faces and,
//! over active triangles, carried by the particles under it (paper §7).
//!
//! Stage 6 of the tick (`update`): each vertex near the tool follows its core face, or the
//! particles that carry it; the far skin a slice of a sweep a tick (`LiveSkin`), and a shed
//! shell's skin fades back to its ties (`SkinLift`). The sub-steps' view of it
//! (`near_tool`): the vertices within the tool's reach, each as a weighted list of the
//! particles under it, so that the tool meets a surface rather than points.

use super::activation::Activation;
use super::embed;
use super::sim::Sim;
use super::state::{SimState, SimWorkspace};
use crate::math::{Mat3, Vec3};
use crate::meshfree;

/// Where a shed shell left the skin (see [`super::tick`], step 3): when the shell is shed, the
/// skin vertices the particles carried sit off their ties by `offset` (the press the particles
/// took), and put back at once the tool's force jumped (measured 0.09-1.4 N in one tick on the
/// synthetic ventricle, `examples/press_sweep.rs`). Instead each stays lifted off its tie by
/// `offset` scaled down linearly from 1 at the shed tick to 0 [`SHED_FADE`] later (or at the
/// end of a shorter pause), in the contact and in the drawn skin. The offsets are constant: the
/// contact's forces stay the gradient of its energy.
#[derive(Debug, Clone)]
pub(crate) struct SkinLift {
    /// Per skin vertex \[m\] (zero unless listed).
    pub offset: Vec<Vec3>,
    /// The lifted vertices.
    pub list: Vec<u32>,
    /// The shed tick, and the ticks the fade takes.
    pub start: u64,
    pub ticks: u64,
}

/// Ticks over which a shed shell's skin returns to its ties (`SkinLift` in this module): 50 ms, so that the
/// largest step measured (1.4 N) reaches the hand as ~0.03 N a millisecond.
pub const SHED_FADE: f64 = 0.05;

impl SkinLift {
    pub(crate) fn new(n_skin: usize) -> SkinLift {
        SkinLift { offset: vec![Vec3::zeros(); n_skin], list: Vec::with_capacity(n_skin), start: 0, ticks: 1 }
    }
    /// The scale of the offsets at tick `t` (0 when nothing is lifted).
    pub fn scale(&self, t: u64) -> f64 {
        if self.list.is_empty() {
            return 0.0;
        }
        (1.0 - t.saturating_sub(self.start) as f64 / self.ticks as f64).max(0.0)
    }
    /// Nothing lifted.
    pub fn clear(&mut self) {
        for &v in &self.list {
            self.offset[v as usize] = Vec3::zeros();
        }
        self.list.clear();
    }
}

/// The ticks of `dt` \[s\] a shed shell's skin takes back to its ties: [`SHED_FADE`], or the
/// shell's pause if shorter; at least one.
pub(crate) fn shed_fade_ticks(o: &super::SimOptions, dt: f64) -> u64 {
    super::sim::ticks_in(SHED_FADE.min(o.shell_fallback.unwrap_or(SHED_FADE)), dt).max(1)
}

/// The skin vertices a tick may need to look at (contact, activation, the skin's update near the
/// tool), and how stale the others may be.
///
/// Every stored skin vertex is within [`SKIN_LIVE_MARGIN`] of where the core (or the
/// particles under it) puts it: the tick bounds how far the core's faces have moved since the
/// last update of the whole skin (`ref_x`, `ref_frames`, [`super::Sim::skin_face_reach`]),
/// plus `slack`, and sweeps the whole skin, a sixteenth a tick, from a quarter of the margin
/// (a vertex the sweep placed at tick `u` is within the travel from the sweep's start to now plus
/// the travel from the start to `u`: hence the slack); only when the bound reaches half the
/// margin anyway (the skin moving over ~0.08 m/s) is the whole skin updated in one tick (1.2 ms
/// on the Rodero ventricle's 31,788 vertices, which the sweep spreads into ~80 us slices). A
/// vertex that stops being
/// carried by particles is put back at its tie at once (`carried`). The list holds the vertices
/// within `r_live + margin + step` of the tool when it was last rebuilt (`ref_tool`; rebuilt
/// once the tool has travelled a margin), plus every vertex moved since. A vertex outside it
/// therefore cannot be within the tool's reach before the next rebuild, and those within the
/// live radius are updated every tick: scanning the list instead of the whole skin changes no
/// contact or activation (the list is kept in index order, so even sums come out in the same
/// order), and costs a tick on the Rodero model's 31,788 skin vertices a few hundred instead
/// of ~32,000 distance tests per scan, with no periodic whole update (a 1 ms spike there).
#[derive(Debug)]
pub(crate) struct LiveSkin {
    /// Vertex indices, ascending.
    pub(crate) list: Vec<u32>,
    /// Per outer vertex: in `list`?
    pub(crate) member: Vec<bool>,
    /// Per outer vertex: its stored place is where the particles under it carried it (not its
    /// tie)?
    pub(crate) carried: Vec<bool>,
    /// `false` until the list is first built (at the start of the first tick after rest, or by
    /// the first whole update): until then every vertex is looked at.
    pub(crate) valid: bool,
    /// `list` gained vertices out of order this tick (sorted before the next use).
    pub(crate) unsorted: bool,
    /// The core's positions \[m\] and face frames at the last whole update of the skin.
    pub(crate) ref_x: Vec<Vec3>,
    pub(crate) ref_frames: Vec<Option<crate::math::Mat3>>,
    /// The tool's centre when the list was last rebuilt \[m\].
    pub(crate) ref_tool: Vec3,
    /// The bound on the skin's travel since the last whole update, as of the last tick \[m\].
    pub(crate) travel: f64,
    /// What the references leave out \[m\]: 0 after a whole update; after a sweep (below), the
    /// most the skin travelled from the sweep's reference while the sweep went on (a vertex the
    /// sweep placed late is that much nearer the reference's successor than the reference says).
    /// Every stored vertex is within `travel + slack` of its place.
    pub(crate) slack: f64,
    /// The sweep of the whole skin in progress, spread over [`SKIN_SWEEP_TICKS`]
    /// ticks instead of one (a whole update of the Rodero ventricle's 31,788 vertices takes
    /// 1.2 ms, more than a haptic tick): the next vertex it places (`None`: no sweep), the core's
    /// positions and face frames when it began, and its own slack so far.
    pub(crate) sweep_next: Option<usize>,
    pub(crate) sweep_ref_x: Vec<Vec3>,
    pub(crate) sweep_ref_frames: Vec<Option<crate::math::Mat3>>,
    pub(crate) sweep_slack: f64,
}

/// [`LiveSkin::iter`]: the list, or every vertex before it is first built.
pub(crate) enum LiveIter<'a> {
    All(std::ops::Range<usize>),
    List(std::slice::Iter<'a, u32>),
}

impl Iterator for LiveIter<'_> {
    type Item = usize;
    fn next(&mut self) -> Option<usize> {
        match self {
            LiveIter::All(r) => r.next(),
            LiveIter::List(l) => l.next().map(|&v| v as usize),
        }
    }
}

impl Clone for LiveSkin {
    fn clone(&self) -> Self {
        LiveSkin {
            list: self.list.clone(),
            member: self.member.clone(),
            carried: self.carried.clone(),
            valid: self.valid,
            unsorted: self.unsorted,
            ref_x: self.ref_x.clone(),
            ref_frames: self.ref_frames.clone(),
            ref_tool: self.ref_tool,
            travel: self.travel,
            slack: self.slack,
            sweep_next: self.sweep_next,
            sweep_ref_x: self.sweep_ref_x.clone(),
            sweep_ref_frames: self.sweep_ref_frames.clone(),
            sweep_slack: self.sweep_slack,
        }
    }
    fn clone_from(&mut self, s: &Self) {
        let LiveSkin {
            list,
            member,
            carried,
            valid,
            unsorted,
            ref_x,
            ref_frames,
            ref_tool,
            travel,
            slack,
            sweep_next,
            sweep_ref_x,
            sweep_ref_frames,
            sweep_slack,
        } = self;
        list.clone_from(&s.list);
        member.clone_from(&s.member);
        carried.clone_from(&s.carried);
        *valid = s.valid;
        *unsorted = s.unsorted;
        ref_x.clone_from(&s.ref_x);
        ref_frames.clone_from(&s.ref_frames);
        *ref_tool = s.ref_tool;
        *travel = s.travel;
        *slack = s.slack;
        *sweep_next = s.sweep_next;
        sweep_ref_x.clone_from(&s.sweep_ref_x);
        sweep_ref_frames.clone_from(&s.sweep_ref_frames);
        *sweep_slack = s.sweep_slack;
    }
}

impl LiveSkin {
    /// At rest: every vertex at its place (the model's outer points, where its tie puts it at
    /// rest), the references the core's rest positions and face frames, the travel since 0. The
    /// first tick then only builds the list around its tool, at its start, instead of placing
    /// the whole skin and looking at every vertex: on the Rodero ventricle that made the first
    /// tick 1.4 ms (now 0.2 ms warm, 0.7 ms in a fresh process), an overrun at the start of
    /// every haptic run (2026-11-27).
    pub(crate) fn at_rest(sim: &super::Sim) -> LiveSkin {
        let (n_outer, n_faces) = (sim.hybrid.outer_points.len(), sim.hybrid.core_faces.len());
        let rest = sim.core.mesh().points();
        let mut ref_frames = vec![None; n_faces];
        super::embed::face_frames(rest, &sim.hybrid.core_faces, &mut ref_frames);
        LiveSkin {
            list: Vec::with_capacity(n_outer),
            member: vec![false; n_outer],
            carried: vec![false; n_outer],
            valid: false,
            unsorted: false,
            ref_x: rest.to_vec(),
            ref_frames,
            ref_tool: Vec3::zeros(),
            travel: 0.0,
            slack: 0.0,
            sweep_next: None,
            sweep_ref_x: vec![Vec3::zeros(); rest.len()],
            sweep_ref_frames: vec![None; n_faces],
            sweep_slack: 0.0,
        }
    }

    /// The vertices to look at, in index order.
    pub(crate) fn iter(&self) -> LiveIter<'_> {
        if self.valid {
            LiveIter::List(self.list.iter())
        } else {
            LiveIter::All(0..self.member.len())
        }
    }

    /// Add vertex `v` (it moved).
    pub(crate) fn add(&mut self, v: usize) {
        if self.valid && !self.member[v] {
            self.member[v] = true;
            self.unsorted |= self.list.last().is_some_and(|&l| l as usize > v);
            self.list.push(v as u32);
        }
    }

    /// Restore index order after [`LiveSkin::add`]s (allocation-free: an unstable sort in place).
    pub(crate) fn sort(&mut self) {
        if self.unsorted {
            self.list.sort_unstable();
            self.unsorted = false;
        }
    }

    /// Rebuild from the whole skin: the vertices within `radius` of `centre`, and those carried
    /// by particles (they must be put back at their ties when their triangles turn inactive).
    pub(crate) fn rebuild(&mut self, skin: &[Vec3], centre: &Vec3, radius: f64) {
        for &v in &self.list {
            self.member[v as usize] = false;
        }
        self.list.clear();
        for (v, x) in skin.iter().enumerate() {
            if self.carried[v] || (x - centre).norm_squared() <= radius * radius {
                self.member[v] = true;
                self.list.push(v as u32);
            }
        }
        self.ref_tool = *centre;
        self.valid = true;
        self.unsorted = false;
    }
}

/// Is outer vertex `v` on a triangle with active particles?
pub(crate) fn over_active(sim: &Sim, activation: &Activation, v: usize) -> bool {
    sim.hybrid.outer_adjacency.vertex_tris.get(v).iter().any(|&t| activation.is_triangle_active(t))
}

/// The skin vertices over active triangles that the tool may reach this tick (`ws.near`), and
/// their lists of the particles under them ([`near_lists`]): `prev` and `tool` are the tool's
/// centre at the tick's start and end \[m\].
pub(super) fn near_tool(sim: &Sim, state: &SimState, ws: &mut SimWorkspace, tool: Vec3, prev: Vec3) {
    let SimState { core, skin, activation, live, .. } = state;
    let o = &sim.options;
    ws.near.clear();
    let reach = o.tool.radius + (tool - prev).norm() + o.activation_margin;
    for v in live.iter() {
        if (skin[v] - tool).norm_squared() < reach * reach && over_active(sim, activation, v) {
            ws.near.push(v);
        }
    }
    near_lists(sim, activation, &core.x, &core.v, ws);
}

/// The skin vertices within the tool's reach this tick, each placed over the particles under its
/// active triangles (see [`over_particles`]) by a list of `(particle, w_p / W)` and a base:
/// the vertex is at `base.0 + sum w_p / W x_p`, moving at `base.1 + sum w_p / W v_p`.
pub(super) struct NearLists<'a> {
    pub near: &'a [usize],
    pub ptr: &'a [usize],
    pub items: &'a [(usize, f64)],
    pub base: &'a [(Vec3, Vec3)],
}

/// Fills `ws.near_ptr`, `ws.near_items` and `ws.near_base` for `ws.near` (allocation-free: their
/// capacities are the model's bounds). The core does not move within a tick, so the ties' part of
/// each vertex's place is computed once here (`ws.tie_x`, `ws.tie_v` hold the active particles').
fn near_lists(sim: &Sim, activation: &Activation, core_x: &[Vec3], core_v: &[Vec3], ws: &mut SimWorkspace) {
    ws.near_ptr.clear();
    ws.near_items.clear();
    ws.near_base.clear();
    ws.near_ptr.push(0);
    ws.uncarried.clear();
    let mut kept = 0;
    for i in 0..ws.near.len() {
        let v = ws.near[i];
        let start = ws.near_items.len();
        ws.near_items.extend(skin_weights(sim, activation, v));
        let wsum: f64 = ws.near_items[start..].iter().map(|&(_, w)| w).sum();
        if !(wsum > 0.0) {
            // No particle carries it: it stays at its tie, and meets the tool in the core's
            // step (step 4).
            ws.near_items.truncate(start);
            ws.uncarried.push(v);
            continue;
        }
        ws.near[kept] = v;
        kept += 1;
        let (mut bx, mut bv) = (sim.skin.position(v, core_x), sim.skin.velocity(v, core_x, core_v));
        for item in &mut ws.near_items[start..] {
            item.1 /= wsum;
            bx -= item.1 * ws.tie_x[item.0];
            bv -= item.1 * ws.tie_v[item.0];
        }
        ws.near_base.push((bx, bv));
        ws.near_ptr.push(ws.near_items.len());
    }
    ws.near.truncate(kept);
}

/// The particles that carry outer vertex `v` (one of whose own triangles is active: every
/// caller asks only for such vertices) over an active zone: those under its active carrier
/// triangles ([`super::sim::SkinCarriers`]: its own triangles, or, where none has a particle under
/// it, the next rings'), with their weights in its placement: each tie's squared depth over its
/// core face, so that the outermost particles, just under the skin, count most.
fn skin_weights<'a>(sim: &'a Sim, activation: &'a Activation, v: usize) -> impl Iterator<Item = (usize, f64)> + 'a {
    let h = &sim.hybrid;
    sim.skin_carriers.get(v).iter().filter(|&&t| activation.is_triangle_active(t)).flat_map(move |&t| {
        (h.tri_particle_ptr[t as usize] as usize..h.tri_particle_ptr[t as usize + 1] as usize).map(move |p| (p, sim.particle_tie.offsets()[p].norm_squared()))
    })
}

/// Where outer vertex `v` is, over active triangles (the caller checks that it is: [`over_active`]):
/// its tie to the core moved by the weighted mean displacement of the particles that carry it
/// from their own ties ([`skin_weights`]); `None` when no active particle carries it. (The sub-steps place the near vertices the same way through
/// [`NearLists`], with the ties computed once a tick.) With the core's face `frames` at `core_x`
/// ([`embed::face_frames`]), the ties take them instead of computing a frame per particle.
pub(crate) fn over_particles(sim: &Sim, activation: &Activation, v: usize, x: &[Vec3], core_x: &[Vec3], frames: Option<&[Option<Mat3>]>) -> Option<Vec3> {
    let tie = &sim.particle_tie;
    let at = |e: &embed::Embedding, i: usize| match frames {
        Some(f) => e.position_framed(i, core_x, f),
        None => e.position(i, core_x),
    };
    let (mut d, mut wsum) = (Vec3::zeros(), 0.0);
    for (p, w) in skin_weights(sim, activation, v) {
        d += w * (x[p] - at(tie, p));
        wsum += w;
    }
    (wsum > 0.0).then(|| at(&sim.skin, v) + d / wsum)
}

/// Skin vertices at their ties, or, over active triangles, carried by the particles under them.
/// Every stored skin vertex is within this \[m\] of its place (see `LiveSkin` in `state.rs`):
/// the whole skin is updated when the core's faces may have carried it half as far since the
/// last whole update, and the vertices within this of the tool's reach every tick.
pub const SKIN_LIVE_MARGIN: f64 = 0.005;

/// Ticks a sweep of the whole skin is spread over (see `LiveSkin`): 1/16 of the Rodero
/// ventricle's skin is ~80 us a tick, where the whole took 1.2 ms in one.
pub const SKIN_SWEEP_TICKS: usize = 16;

/// The radius \[m\] within which the skin is updated every tick: the tool's reach, two of its
/// steps (it moves before the next tick's contact) and [`SKIN_LIVE_MARGIN`] (a stale vertex is
/// no farther than that from its place).
pub(super) fn live_radius(o: &super::SimOptions, dt: f64) -> f64 {
    o.tool.radius + o.activation_margin + 2.0 * o.max_tool_speed * dt + SKIN_LIVE_MARGIN
}

/// The radius \[m\] of the list of skin vertices a tick looks at (see `LiveSkin`): the live
/// radius, a margin (the list is rebuilt once the tool has travelled that far) and a tool's step.
pub(super) fn list_radius(o: &super::SimOptions, dt: f64) -> f64 {
    live_radius(o, dt) + SKIN_LIVE_MARGIN + o.max_tool_speed * dt
}

/// How far \[m\] the skin's ties may have moved since the core was at `ref_x` with face frames
/// `ref_frames`: over the faces carrying skin, `sum |w| max |dx| + |dR|_F |o|` (infinite where a
/// face's frame turned degenerate or back).
fn skin_travel(sim: &Sim, core_x: &[Vec3], frames: &[Option<Mat3>], ref_x: &[Vec3], ref_frames: &[Option<Mat3>]) -> f64 {
    let mut travel = 0.0f64;
    for (f, (&(w, o), face)) in sim.skin_face_reach.iter().zip(&sim.hybrid.core_faces).enumerate() {
        if w == 0.0 && o == 0.0 {
            continue;
        }
        let dx = face.iter().map(|&a| (core_x[a] - ref_x[a]).norm()).fold(0.0, f64::max);
        let dr = match (frames[f], ref_frames[f]) {
            (Some(a), Some(b)) => (a - b).norm(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        };
        travel = travel.max(w * dx + dr * o);
    }
    travel
}

/// The core's face frames are computed once (`frames`), not per vertex, and the vertices over
/// active triangles are found from the active triangles' list (`over[v] == stamp`) rather than
/// by asking every vertex's triangles (or every active region's: neighbouring regions share
/// most of their triangles, and that loop was 2% of the Rodero tick). Then, unless the skin's travel bound calls for a whole update: the
/// vertices of `live` within [`live_radius`] of the tool, and those no longer carried by
/// particles, go to their ties (a fine outer surface, the Rodero model's 31,788 vertices, made
/// the whole skin's update a third of its tick); the list is rebuilt when the tool has moved
/// [`SKIN_LIVE_MARGIN`] since it last was. Every vertex moved here joins `live`.
#[allow(clippy::too_many_arguments)]
fn update_skin(
    sim: &Sim,
    activation: &Activation,
    particles: &meshfree::ParticleState,
    core_x: &[Vec3],
    frames: &mut [Option<Mat3>],
    over: &mut [u64],
    stamp: u64,
    tool: Vec3,
    dt: f64,
    live: &mut LiveSkin,
    skin: &mut [Vec3],
) -> usize {
    embed::face_frames(core_x, &sim.hybrid.core_faces, frames);
    let frames = &*frames;
    let place = |v: usize, over: bool| {
        let carried = if over { over_particles(sim, activation, v, &particles.x, core_x, Some(frames)) } else { None };
        carried.unwrap_or_else(|| sim.skin.position_framed(v, core_x, frames))
    };
    for &t in activation.active_triangles() {
        for &v in &sim.hybrid.outer_tris[t as usize] {
            if over[v] != stamp {
                over[v] = stamp;
                skin[v] = place(v, true);
                live.carried[v] = true;
                live.add(v);
            }
        }
    }
    live.sort();
    let r_live = live_radius(&sim.options, dt);
    let r_list = list_radius(&sim.options, dt);
    live.travel = skin_travel(sim, core_x, frames, &live.ref_x, &live.ref_frames);
    // A sweep's vertices were placed from the core at or after its start: within its reference's
    // travel plus what the skin travelled from it while the sweep went on.
    let sweep_travel = match live.sweep_next {
        Some(_) => {
            let t = skin_travel(sim, core_x, frames, &live.sweep_ref_x, &live.sweep_ref_frames);
            live.sweep_slack = live.sweep_slack.max(t);
            t
        }
        None => 0.0,
    };
    let bound = (live.travel + live.slack).max(if live.sweep_next.is_some() { sweep_travel + live.sweep_slack } else { 0.0 });
    if !(2.0 * bound <= SKIN_LIVE_MARGIN) {
        // The whole skin at once (a sweep could not keep up): every stored vertex back at its
        // place.
        for v in 0..skin.len() {
            if over[v] != stamp {
                skin[v] = place(v, false);
                live.carried[v] = false;
            }
        }
        live.ref_x.copy_from_slice(core_x);
        live.ref_frames.copy_from_slice(frames);
        (live.travel, live.slack, live.sweep_next) = (0.0, 0.0, None);
        live.rebuild(skin, &tool, r_list);
        return skin.len();
    }
    // Past a quarter of the margin, a sweep of the whole skin begins, a slice a tick: it ends
    // before the bound reaches half the margin unless the skin moves faster than ~0.08 m/s, when
    // the whole update above takes over. (At an eighth, sweeps ran twice as often in a slow press
    // for no gain: tests/runtime_hand.rs counts them.)
    if live.sweep_next.is_none() && 4.0 * (live.travel + live.slack) > SKIN_LIVE_MARGIN {
        live.sweep_ref_x.copy_from_slice(core_x);
        live.sweep_ref_frames.copy_from_slice(frames);
        (live.sweep_next, live.sweep_slack) = (Some(0), 0.0);
    }
    let mut refreshed = 0;
    if let Some(start) = live.sweep_next {
        let n = skin.len();
        let end = (start + n.div_ceil(SKIN_SWEEP_TICKS)).min(n);
        refreshed = end - start;
        for v in start..end {
            if over[v] != stamp {
                skin[v] = place(v, false);
                live.carried[v] = false;
            }
        }
        if end < n {
            live.sweep_next = Some(end);
        } else {
            // Done: the sweep's reference is the skin's.
            std::mem::swap(&mut live.ref_x, &mut live.sweep_ref_x);
            std::mem::swap(&mut live.ref_frames, &mut live.sweep_ref_frames);
            (live.travel, live.slack, live.sweep_next) = (sweep_travel, live.sweep_slack, None);
            live.rebuild(skin, &tool, r_list);
        }
    }
    for k in 0..live.list.len() {
        let v = live.list[k] as usize;
        if over[v] != stamp && (live.carried[v] || (skin[v] - tool).norm_squared() <= r_live * r_live) {
            skin[v] = place(v, false);
            live.carried[v] = false;
        }
    }
    if !((tool - live.ref_tool).norm() <= SKIN_LIVE_MARGIN) {
        live.rebuild(skin, &tool, r_list);
    }
    refreshed
}

/// Stage 6, what the tick owes of the skin (`super::finish_tick`): the vertices near the tool
/// and over active triangles placed, a slice of the far skin's sweep, and a shed shell's skin as
/// lifted off its ties. Returns the vertices refreshed away from the tool (0 when nothing was
/// owed).
pub(super) fn update(sim: &Sim, state: &mut SimState, ws: &mut SimWorkspace) -> usize {
    let SimState { core, particles, skin, tool, activation, ticks, live, lift, skin_owed, dt, .. } = state;
    let Some(tool) = *tool else { return 0 };
    if !std::mem::replace(skin_owed, false) {
        return 0;
    }
    // Marks of this update (the workspace's count, as the tick's own).
    ws.epoch += 1;
    let refreshed = update_skin(sim, activation, particles, &core.x, &mut ws.frames, &mut ws.over, ws.epoch, tool, *dt, live, skin);
    // A shed shell's skin, lifted off its ties as the next tick's contact will see it (the tick
    // is already counted: its successor's scale).
    if !lift.list.is_empty() {
        let scale = lift.scale(*ticks);
        for &v in &lift.list {
            let v = v as usize;
            skin[v] = sim.skin.position_framed(v, &core.x, &ws.frames) + scale * lift.offset[v];
        }
        if scale == 0.0 {
            lift.clear();
        }
    }
    refreshed
}
