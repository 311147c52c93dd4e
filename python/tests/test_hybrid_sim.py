"""palpate.HybridSim: the hybrid model you can touch (issue 12, in progress).

What a wrong implementation would do: return a force with the tool away from the tissue, or one
that pulls the tool in (the tissue must push back along the outward normal); leave particles
active with no contact ever made; hold the GIL through a tick; accept a non-finite tool position
or tool parameters.
"""
import threading
import time

import numpy as np
import pytest

import palpate


@pytest.fixture(scope="module")
def ventricle():
    return palpate.build_shape("ventricle")


@pytest.fixture(scope="module")
def material():
    return palpate.Material(young=3e4, poisson=0.4, density=1000.0)


def _press_point(sim):
    s = sim.surface
    # The outer vertex nearest to (x_max, 0, 20 mm) and its direction from the axis.
    target = np.array([s[:, 0].max(), 0.0, 0.02])
    p = s[np.argmin(np.linalg.norm((s - target)[:, 1:], axis=1) + 10 * (s[:, 0] < 0))]
    n = np.array([p[0], p[1], 0.0])
    return p, n / np.linalg.norm(n)


def test_press_pushes_back_and_release_lets_go(ventricle, material):
    sim = palpate.HybridSim(ventricle, material)
    assert sim.n_particles == len(ventricle.particles) and sim.active.size == 0
    p, n = _press_point(sim)
    r = 0.005
    far = sim.step(p + n * (r + 0.01))
    assert np.all(far == 0.0) and sim.last["active"] == 0
    forces = []
    for k in range(300):          # 3 mm deep over 0.3 s
        depth = 3e-3 * (k + 1) / 300
        forces.append(sim.step(p + n * (r - depth)))
    f = forces[-1]
    assert np.all(np.isfinite(f))
    assert f @ n > 0.01, f"the tissue should push the tool out along the normal, got {f} N"
    assert 0 < sim.last["active"] <= sim.n_particles and sim.last["particle_contacts"] > 0
    assert sim.surface.shape == (len(ventricle.outer_points), 3) and np.all(np.isfinite(sim.surface))
    assert sim.particle_positions().shape == (sim.n_particles, 3)
    for _ in range(300):
        sim.step(p + n * (r + 0.01))
    assert np.all(sim.step(p + n * (r + 0.01)) == 0.0)
    assert sim.active.size == 0, "regions must leave once the tool is gone for longer than they linger"
    assert sim.time == pytest.approx(0.602) and sim.ticks == 602


def test_unit_mistakes_warn_or_are_refused(ventricle, material):
    """Issue 37: values most likely in the wrong unit (E typed in kPa, a tool radius in mm, a tool
    target in mm) warn with ``UnitWarning`` naming the unit that fits; ``strict_units=True``
    refuses them (the target before the tick: nothing moves). Plausible values say nothing."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim = palpate.HybridSim(ventricle, material)
        p, n = _press_point(sim)
        sim.step(p + n * 0.004)
    with pytest.warns(palpate.UnitWarning, match=r"typed in kPa\? 30 kPa is 30000 Pa"):
        palpate.HybridSim(ventricle, palpate.Material(young=30.0, poisson=0.4))
    with pytest.warns(palpate.UnitWarning, match=r"tool radius 5 m is over 5 cm.*5 mm is 0.005 m"):
        palpate.HybridSim(ventricle, material, tool_radius=5.0)
    far = p * 1e3                                     # the same point in mm
    with pytest.warns(palpate.UnitWarning, match="m from the organ"):
        sim.step(far)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim.step(far)                                 # once a simulation
    with pytest.raises(palpate.ParameterError, match=r"Young's modulus 30 Pa.*\(strict_units\)"):
        palpate.HybridSim(ventricle, palpate.Material(young=30.0, poisson=0.4), strict_units=True)
    with pytest.raises(palpate.ParameterError, match=r"10 MPa"):
        palpate.HybridSim(ventricle, palpate.Material(young=3e9, poisson=0.4), strict_units=True)
    strict = palpate.HybridSim(ventricle, material, strict_units=True)
    assert strict.options["strict_units"] is True
    with pytest.raises(palpate.ParameterError, match="from the organ"):
        strict.step(far)
    assert strict.ticks == 0 and strict.tool_position is None
    assert issubclass(palpate.UnitWarning, UserWarning)


def test_bad_input_is_refused(ventricle, material):
    with pytest.raises(ValueError, match="tool_radius"):
        palpate.HybridSim(ventricle, material, tool_radius=-1.0)
    with pytest.raises(ValueError, match="tool_area_stiffness"):
        palpate.HybridSim(ventricle, material, tool_area_stiffness=float("nan"))
    sim = palpate.HybridSim(ventricle, material)
    with pytest.raises(ValueError, match="tool_centre"):
        sim.step([np.nan, 0.0, 0.0])
    with pytest.raises(palpate.StepError):
        sim.step([0.0, 0.0, 0.0], dt=0.0)
    assert sim.ticks == 0


def test_ticks_release_the_gil(ventricle, material):
    sim = palpate.HybridSim(ventricle, material)
    p, n = _press_point(sim)
    counter = [0]
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            counter[0] += 1

    t = threading.Thread(target=spin)
    t.start()
    t0 = time.perf_counter()
    for k in range(100):
        sim.step(p + n * (0.005 - 2e-3 * k / 100))
    stop.set()
    t.join()
    assert counter[0] > 1000 and time.perf_counter() > t0


def test_the_implicit_exchange_keeps_the_shell_springs_at_the_tissues_stiffness(ventricle, material):
    """``implicit_exchange=True`` (the default): the springs tying the shell to the core are ``E h``
    (with False they are capped by the explicit exchange's stability, far below it); a press with
    it pushes back, harder than with the capped springs, and the option survives a pickle."""
    import pickle

    capped = palpate.HybridSim(ventricle, material, implicit_exchange=False)
    full = palpate.HybridSim(ventricle, material)
    assert capped.options["implicit_exchange"] is False and full.options["implicit_exchange"] is True
    e_h = material.young * ventricle.spacing
    assert full.options["coupling_stiffness"] == pytest.approx(e_h, rel=1e-12)
    assert capped.options["coupling_stiffness"] < 0.5 * e_h
    assert pickle.loads(pickle.dumps(full)).options["implicit_exchange"] is True
    assert pickle.loads(pickle.dumps(capped)).options["implicit_exchange"] is False
    p, n = _press_point(full)
    forces = []
    for sim in (capped, full):
        for k in range(400):
            f = sim.step(p + n * (0.005 - 3e-3 * min(1.0, (k + 1) / 300)))
        assert np.isfinite(f).all()
        forces.append(float(f @ n))
    assert 0.0 < forces[0] < forces[1], forces


def test_core_contact_stiffness_and_the_shell_options_survive_a_pickle(ventricle, material):
    """``core_contact_stiffness`` [N/m] sets the tool's wall against the core's surface; it, and
    ``shell_fallback`` / ``shell_pause``, come back from a pickle (the pickle rebuilt the
    simulation from the other options only, and a non-default fallback came back as the default);
    a nonsense stiffness is refused by name."""
    import pickle

    sim = palpate.HybridSim(ventricle, material, core_contact_stiffness=500.0, shell_fallback=False)
    assert sim.options["core_contact_stiffness"] == 500.0
    assert palpate.HybridSim(ventricle, material).options["core_contact_stiffness"] == 2000.0
    back = pickle.loads(pickle.dumps(sim))
    for k in ("core_contact_stiffness", "shell_fallback", "shell_pause", "tool_area_stiffness"):
        assert back.options[k] == sim.options[k], k
    paused = pickle.loads(pickle.dumps(palpate.HybridSim(ventricle, material, shell_pause=0.007)))
    assert paused.options["shell_fallback"] is True and paused.options["shell_pause"] == 0.007
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(palpate.ParameterError, match="core_contact_stiffness"):
            palpate.HybridSim(ventricle, material, core_contact_stiffness=bad)


def test_options_tool_position_and_reset(ventricle, material):
    sim = palpate.HybridSim(ventricle, material, tool_radius=0.004, activation_margin=5e-4, max_tool_speed=0.2,
                            linger=0.01, max_substeps=40)
    o = sim.options
    assert (o["tool_radius"], o["activation_margin"], o["max_tool_speed"], o["linger"], o["max_substeps"]) == \
        (0.004, 5e-4, 0.2, 0.01, 40)
    assert o["coupling_stiffness"] > 0 and o["confinement_stiffness"] > 0 and sim.tool_radius == 0.004
    assert sim.tool_position is None
    far = np.array([1.0, 1.0, 1.0])
    sim.step(far)
    # The device jumps 10 mm: the simulated tool follows at most at max_tool_speed, whatever the
    # tick's length (0.2 mm in 1 ms, 0.8 mm more in 4 ms).
    sim.step(far + [0.01, 0.0, 0.0])
    assert np.linalg.norm(sim.tool_position - far) == pytest.approx(2e-4)
    sim.step(far + [0.01, 0.0, 0.0], dt=4e-3)
    assert np.linalg.norm(sim.tool_position - far) == pytest.approx(1e-3)
    sim.reset()
    assert sim.ticks == 0 and sim.time == 0.0 and sim.tool_position is None and len(sim.active) == 0
    for bad in [dict(activation_margin=-1e-3), dict(max_tool_speed=0.0), dict(max_substeps=0), dict(linger=-0.1),
                dict(linger=float("nan")), dict(shell_pause=-1.0)]:
        key = next(iter(bad))
        with pytest.raises(ValueError, match=key):
            palpate.HybridSim(ventricle, material, **bad)


def test_mass_scaling_is_reported_and_can_be_turned_off(material):
    """The shell's selective mass scaling (default quantile 0.95): on the paper's ellipsoids (with
    the paper's 192-tet core) it adds about 1% of the shell's mass and lowers its top frequency;
    quantile 1.0 scales nothing; on the synthetic ventricle's regular lattice it is not worth it and
    the masses stay physical (as on the ellipsoids with the default 900-tet core)."""
    ell = palpate.build_shape("ellipsoids", core_triangles=64)
    on = palpate.HybridSim(ell, material).options
    off = palpate.HybridSim(ell, material, mass_scaling=1.0).options
    assert on["mass_scaling"] == 0.95 and on["mass_scaling_applied"], on
    assert 0.0 < on["added_mass_fraction"] < 0.03 and on["scaled_particles"] > 0
    assert not off["mass_scaling_applied"] and off["added_mass_fraction"] == 0.0 and off["scaled_particles"] == 0
    assert on["omega_max"] < 0.95 * off["omega_max"], (on["omega_max"], off["omega_max"])
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="mass_scaling"):
            palpate.HybridSim(ell, material, mass_scaling=bad)


def _deep_press(sim, m, depth, ticks, force_cap=None):
    """Press along the inward normal at the probe point (palpate.touch.probe_point) to ``depth``
    [m] over ``ticks`` ticks, then hold 100 ticks; with ``force_cap`` [N], stop advancing once the
    force on the tool reaches it. Returns the largest |force| [N]; a failed tick raises."""
    from palpate import bench_hybrid

    _, p, n_in, _ = bench_hybrid.probe(m)
    r, d, fmax = sim.tool_radius, 0.0, 0.0
    for k in range(ticks + 100):
        f = np.linalg.norm(sim.step(p - n_in * (r - d)))
        fmax = max(fmax, f)
        if force_cap is None or f < force_cap:
            d = min(depth, d + depth / ticks)
    return fmax


def test_the_rodero_ventricle_survives_a_15_mm_press_and_a_press_toward_2_n(lv_path, material):
    """Every shipped model stays finite under a 15 mm press and a press toward 2 N (capped at
    20 mm of travel: 2 N is more than these soft organs give; tests/runtime_hand.rs does the
    synthetic ventricle and the ellipsoids)."""
    m = palpate.build_shape("rodero")
    sim = palpate.HybridSim(m, material)
    f15 = _deep_press(sim, m, 15e-3, 300)
    sim.reset()
    f2 = _deep_press(sim, m, 20e-3, 400, force_cap=2.0)
    assert 0.05 < f15 < 5.0 and 0.05 < f2 <= 5.0, (f15, f2)
    assert np.isfinite(sim.surface).all() and np.isfinite(sim.particle_positions()).all()


def _sweep_probe(m, height, theta):
    """examples/press_sweep.rs's probe: the outer vertex nearest the horizontal ray from the outer
    surface's centroid at ``height`` (a fraction of the model's) and angle ``theta`` [rad], and
    the ray's unit direction (outward, horizontal)."""
    outer = m.outer_points
    lo, hi = outer.min(axis=0), outer.max(axis=0)
    z = lo[2] + height * (hi[2] - lo[2])
    u = np.array([np.cos(theta), np.sin(theta), 0.0])
    d = outer - outer.mean(axis=0)
    side = d - np.outer(d @ u, u)
    off_ray = side[:, 0] ** 2 + side[:, 1] ** 2 + (outer[:, 2] - z) ** 2
    return outer[np.argmin(np.where(d @ u > 0, off_ray, np.inf))], u


def test_a_hard_press_held_on_rodero_does_not_chatter(lv_path, material):
    """The tool pressed 11.35 mm in and held near the Rodero ventricle's base (examples/
    press_sweep.rs's probe at 4/5 of the height, 3.44 rad). There the skin vertices with no
    particle under their own triangles had stayed at their ties, and their contact, held over the
    core's 1 ms step as an explicit force, made the force alternate tick by tick (2.2 <-> 4.8 N,
    median change 1.3 N a tick, as long as the tool was held). Now such contact is inside the
    core's implicit step (runtime/core_contact.rs) and those vertices are carried by the
    particles of the next rings (SkinCarriers): over 200 ticks of the hold (undamped tissue) the
    force changes by at most a few mN a tick (asserted: median 0.03 N, largest 0.3 N, where the
    chatter gave ~1.3 N and ~2.5 N)."""
    m = palpate.build_shape("rodero")
    sim = palpate.HybridSim(m, material)
    p, u = _sweep_probe(m, 0.8, np.pi + 0.3)
    r = sim.tool_radius
    forces = []
    for k in range(328 + 250):
        depth = min(11.35e-3, -5e-3 + 5e-5 * k)  # 50 mm/s from 5 mm outside, then held
        f = sim.step(p + u * (r - depth))
        assert np.isfinite(f).all()
        forces.append(np.linalg.norm(f))
    assert not sim.last["shell_off"], "the shell carries the press (it is not shed)"
    hold = np.array(forces[-200:])
    assert hold.min() > 0.2, hold.min()  # the tool still presses (0.5 N)
    change = np.abs(np.diff(hold))
    assert np.median(change) < 0.03 and change.max() < 0.3, (np.median(change), change.max())


def test_a_press_toward_5_n_on_rodero_meets_the_core_as_a_wall(lv_path, material):
    """A hand pressing toward 5 N at 50 mm/s where the Rodero ventricle's shell is thin
    (examples/press_sweep.rs's probe at 3/5 of the height, 2.39 rad): the tool reaches the core.
    The core's surface met the tool through its nodes, at 60 N/m a point, which let the tool
    through the organ (the force peaked at 2.75 N, then fell to zero with the tool 25 mm in); now
    the core's surface is a stiff, signed wall (runtime/core_contact.rs): 5 N is reached at
    2.7 mm of travel, the force changing by at most 0.12 N a tick on the way (asserted: 0.3 N),
    and ``last["core_contacts"]`` says the tool touches the core."""
    m = palpate.build_shape("rodero")
    sim = palpate.HybridSim(m, material)
    p, u = _sweep_probe(m, 0.6, 2 * np.pi / 3 + 0.3)
    r = sim.tool_radius
    forces, core = [], 0
    for k in range(600):
        depth = min(25e-3, -5e-3 + 5e-5 * k)  # 50 mm/s from 5 mm outside, 25 mm at most
        f = np.linalg.norm(sim.step(p + u * (r - depth)))
        assert np.isfinite(f)
        forces.append(f)
        core = max(core, sim.last["core_contacts"])
        if f >= 5.0:
            break
    assert forces[-1] >= 5.0, f"the organ gave at most {max(forces):.3f} N over 25 mm of travel"
    assert core == 1, "the tool never touched the core"
    assert np.abs(np.diff(forces)).max() < 0.3, np.abs(np.diff(forces)).max()


def test_a_failed_shell_is_shed_and_the_press_goes_on(ventricle, material):
    """``shell_fallback`` (default True): a shell under-stepped by its cap (3 sub-steps a tick
    where it needs ~12) diverges under a 3 mm press; the tick goes on with the core and the skin
    (``last["shell_failed"]``), the shell stays off ``shell_pause`` seconds (``shell_off``), the
    force stays finite and pushes back. With ``shell_fallback=False`` the same press raises
    ``StepError`` with the core as it was. The contact is softer than the default (1e7 N/m^3,
    26 N/m on this skin's 2.6 mm^2 a vertex): with the default (8.6e7), or with 2.3e7, the
    under-stepped shell fails in the first tick, before it has carried the skin anywhere (nothing
    to lift); with 4e6 or 1e7 in the second (measured). The skin the shell left fades back
    under the tool, so the tick right after a failure at a shallow press may touch nothing: the
    force never pulls, and pushes back whenever the skin is touched."""
    p, n = None, None
    soft = dict(max_substeps=3, shell_pause=0.02, tool_area_stiffness=1e7)
    for fallback in (True, False):
        sim = palpate.HybridSim(ventricle, material, shell_fallback=fallback, **soft)
        assert sim.options["shell_fallback"] is fallback and sim.options["shell_pause"] == (0.02 if fallback else None)
        p, n = _press_point(sim)
        failed, off, raised, pushed = [], 0, False, 0
        copy, compared = None, False
        for k in range(150):
            depth = 3e-3 * min(1.0, (k + 1) / 50)
            x0 = sim.core_positions.copy()
            try:
                f = sim.step(p + n * (0.005 - depth))
            except palpate.StepError as e:
                assert not fallback and "diverging" in str(e)
                assert (sim.core_positions == x0).all()
                raised = True
                break
            assert np.all(np.isfinite(f)) and np.all(np.isfinite(sim.surface))
            if sim.last["shell_failed"]:
                failed.append(k)
                assert sim.last["active"] == 0 and sim.active.size == 0
            off += sim.last["shell_off"]
            assert f @ n >= 0.0, "the organ never pulls the tool"
            if sim.last["shell_off"]:
                pushed += f @ n > 0.0
                if sim.last["skin_contacts"]:
                    assert f @ n > 0.0, "the skin and the core push back while the shell is off"
            if fallback and failed and k == failed[0] + 5:
                # Mid-fade: the skin the shell left is lifted off its ties, and a restored copy
                # (through a pickle-able dict) ticks as the original, bit for bit.
                state = sim.get_state()
                assert state["skin_lift_vertices"].size > 0 and state["skin_lift_offsets"].shape == (state["skin_lift_vertices"].size, 3)
                assert state["skin_lift_start"] == failed[0]
                copy = palpate.HybridSim(ventricle, material, shell_fallback=True, **soft)
                stale = dict(state, skin_lift_vertices=np.array([10**9]), skin_lift_offsets=np.zeros((1, 3)))
                with pytest.raises(ValueError):
                    copy.set_state(stale)
                copy.set_state(state)
            elif copy is not None:
                assert (copy.step(p + n * (0.005 - depth)) == f).all(), "the restored copy's tick differs"
                copy, compared = None, True
        if fallback:
            assert failed and not raised and off >= 20 and compared, (failed, off, compared)
            # The hand feels the organ through the pause (the first tick or two after a failure
            # at a shallow press may find the skin lifted away from the tool).
            assert pushed >= off - 2, (pushed, off)
            # The shell comes back after each pause (and, under-stepped, fails again).
            assert all(b - a >= 21 for a, b in zip(failed, failed[1:])), failed
        else:
            assert raised
