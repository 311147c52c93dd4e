"""``palpate bench protocol|particles|hybrid|haptic|view|sweep``: the shared FEM probe case
(:mod:`palpate.bench`), the per-tick cost of a particle body (:mod:`palpate.bench.particles`) and
of the hybrid simulation at a chosen active count (:mod:`palpate.bench.hybrid`), the haptic loop's
timing (:mod:`palpate.bench.haptic`), what the web viewer costs that loop
(:mod:`palpate.bench.view`) and the batch-study runner's overhead (:mod:`palpate.bench.sweep`).
The defaults are those modules' (the benchmarks' definitions)."""
from __future__ import annotations

import json
import math
import sys

from .. import __version__
from .. import _progress
from .. import bench
from ..bench import hybrid as bh
from ..bench import particles as bp
from ._common import FAILED, Fail, RunFailed, Usage, add_physics_rate, add_quiet, fmt_mm, load_hybrid_model, load_view_model, num, palpate_errors, physics_rate
from .._extras import install_hint


def add_parser(sub) -> None:
    b = sub.add_parser("bench", help="benchmarks")
    bsub = b.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    p = bsub.add_parser("protocol", help="the shared LV probe case (shared/bench/PROTOCOL.md)",
                        description="Run the shared benchmark case on MESH (.msh, .vtu or .npz in mesh units; "
                                    f"'{bench.GENERATED}' for the generated paper-size ellipsoid), or --all.")
    p.add_argument("mesh", nargs="?", metavar="MESH")
    p.add_argument("--all", action="store_true", help=f"the {len(bench.MESHES)} shared meshes and the generated 192-tet "
                        "closed ellipsoid (same probe; its nodes with z <= 0, the lower half-shell, are fixed)")
    p.add_argument("--steps", type=int, default=bench.STEPS,
                   help=f"steps of {num(bench.DT * 1e3)} ms (default {bench.STEPS})")
    p.add_argument("--json", action="store_true", help="one JSON object per mesh (JSON lines)")
    add_quiet(p)
    p.add_argument("--integrator", default="backward-euler", choices=list(bench.INTEGRATORS),
                   help="backward-euler (the default: quasi-Newton), newton, linearised, semi-implicit, "
                        "semi-implicit-stable")
    p.add_argument("--force", type=float, default=bench.FORCE, metavar="F",
                   help=f"total probe force [N] (default {num(bench.FORCE)}, the protocol's; same loaded nodes)")
    p.add_argument("--newton", choices=["auto", "on", "off"], default="auto",
                   help="also run converged Newton for rel_L2_vs_newton (auto: meshes up to "
                        f"{bench.NEWTON_REFERENCE_MAX_TETS // 1000}k tets)")
    p.add_argument("--max-wall", type=float, default=None, metavar="S",
                   help="stop a run after S seconds of stepping (default: no cap)")
    p.set_defaults(func=cmd_bench_protocol)

    sizes = ", ".join(map(str, bp.ALL))
    q = bsub.add_parser("particles", help="per-tick cost of a meshfree particle body (an LV-shell cluster of N particles)",
                        description="Time 1 ms ticks of the N particles of the LV shell fill nearest the probe point "
                                    f"(see palpate/bench/particles.py), or --all: N = {sizes}.")
    q.add_argument("n", nargs="?", type=int, metavar="N", help="number of (active) particles")
    q.add_argument("--all", action="store_true", help=f"N = {sizes}")
    q.add_argument("--spacing", type=float, default=bp.SPACING, metavar="M",
                   help=f"lattice spacing [m] (default {num(bp.SPACING)})")
    q.add_argument("--kernel", default="wendland", choices=list(bp.KERNELS))
    q.add_argument("--support", type=float, default=bp.SUPPORT_FACTOR, metavar="F",
                   help=f"kernel support radius in lattice spacings (default {num(bp.SUPPORT_FACTOR)})")
    q.add_argument("--ticks", type=int, default=bp.TICKS, help=f"ticks of 1 ms to time (default {bp.TICKS})")
    q.add_argument("--json", action="store_true", help="one JSON object per N (JSON lines)")
    add_quiet(q)
    q.add_argument("--max-wall", type=float, default=None, metavar="S",
                   help="stop a case after S seconds of ticks (default: no cap)")
    q.set_defaults(func=cmd_bench_particles)

    h = bsub.add_parser("hybrid", help="per-tick cost of the hybrid simulation (HybridSim) with about N particles active",
                        description="Calibrate the tool radius so that about N particles are active under a held "
                                    f"{num(bh.DEPTH * 1e3)} mm press at the probe point of MODEL (a palpate model file, "
                                    "or a shape: ellipsoids, ventricle, rodero), then time each tick of a scripted "
                                    f"press, hold, {num(bh.SLIDE * 1e3)} mm slide and release (one thread; see "
                                    "palpate/bench/hybrid.py for the probe point and the calibration rule). "
                                    "Exit 3 if a tick fails.")
    h.add_argument("model", metavar="MODEL", help="model file (palpate build) or ellipsoids|ventricle|rodero")
    h.add_argument("--active", type=int, required=True, metavar="N", help="target number of active particles")
    h.add_argument("--ticks", type=int, default=bh.TICKS,
                   help=f"ticks of {num(bh.DT * 1e3)} ms in the timed script (default {bh.TICKS}, at least {bh.MIN_TICKS})")
    h.add_argument("--radius", type=float, default=None, metavar="M",
                   help="tool radius [m]: skip the calibration")
    h.add_argument("--mass-scaling", type=float, default=None, metavar="Q",
                   help="the shell's mass-scaling quantile in (0, 1] (default: HybridSim's, 0.95; 1 scales nothing)")
    h.add_argument("--tool-area-stiffness", type=float, default=None, metavar="K",
                   help="the contact's penalty per unit of skin area [N/m^3] (default: HybridSim's, 12 E*/min(R, 4h) with h the lattice spacing)")
    h.add_argument("--explicit-exchange", action="store_true",
                   help="the shell's springs capped by the explicit exchange's stability (HybridSim(implicit_exchange=False), "
                        "for comparison)")
    h.add_argument("--json", action="store_true", help="one JSON object")
    add_quiet(h)
    h.set_defaults(func=cmd_bench_hybrid)
    _add_haptic(bsub)
    _add_view(bsub)
    _add_sweep(bsub)


def _add_sweep(bsub) -> None:
    w = bsub.add_parser("sweep", help="the batch-study runner's overhead and 2-worker speed-up (palpate sweep)",
                        description="A study of N probe scenarios on a protocol mesh run as a plain Python loop, then "
                                    "by the Dask runner with 1 and 2 local workers: scenarios per second, the runner's "
                                    "overhead per scenario and the 2-worker speed-up (palpate/bench/sweep.py).")
    w.add_argument("mesh", nargs="?", default="1350", metavar="MESH",
                   help="190, 1350, 10k, 50k (the shared lv_* meshes) or ellipsoid_192 (default 1350)")
    w.add_argument("--scenarios", type=int, default=64, metavar="N", help="scenarios (default 64)")
    w.add_argument("--steps", type=int, default=1000, help="steps of 1 ms a scenario (default 1000)")
    w.add_argument("--repeat", type=int, default=3, help="rounds of the three runs; medians reported (default 3)")
    w.add_argument("--json", action="store_true", help="one JSON object")
    w.set_defaults(func=cmd_bench_sweep)


def cmd_bench_sweep(a) -> int:
    import json as _json

    from ..bench import sweep as sb

    if a.scenarios < 2:
        raise Usage("palpate bench sweep: --scenarios must be at least 2")
    if not 1 <= a.repeat <= 100:
        raise Usage("palpate bench sweep: --repeat must be 1 to 100")
    r = sb.run(a.mesh, a.scenarios, a.steps, a.repeat, log=None if a.json else print)
    if a.json:
        print(_json.dumps(r))
    else:
        print(f"palpate bench sweep: {r['scenarios']} scenarios of {r['steps']} steps on {r['mesh']}: "
              f"loop {r['loop_per_s']:.2f}/s, 1 worker {r['worker1_per_s']:.2f}/s, 2 workers {r['worker2_per_s']:.2f}/s; "
              f"runner overhead {100 * r['overhead_per_scenario']:.1f}% a scenario ({100 * r['overhead_per_scenario_steady']:.1f}% past "
              f"the cluster's {r['cluster_start_stop_s']:.2f} s start and stop; importing Dask took {r['startup_s']:.2f} s once); speed-up 2 over 1: "
              f"{r['speedup_2_over_1']:.2f}x ({r['speedup_2_over_1_steady']:.2f}x past the start-up; two bare processes "
              f"without Dask: {r['bare_speedup_2']:.2f}x over the loop); medians of {r['repeat']}")


def _add_view(bsub) -> None:
    w = bsub.add_parser("view", help="what the web viewer (palpate view) costs the haptic loop",
                        description="Run the haptic loop on MODEL with a simulated hand dragged across the probe point "
                                    "(20 Hz targets, as a mouse drag): alone, under palpate view with no page, with the page "
                                    "open in the system's headless Chromium (niced), and alone again; report the loop's period "
                                    "percentiles and overruns, and the viewer's frame rates (palpate/bench/view.py).")
    w.add_argument("model", metavar="MODEL", nargs="?", default="rodero",
                   help="as palpate view's: a hybrid model or shape, or a full-FEM tet mesh, scene or protocol mesh name")
    w.add_argument("--unit", choices=("m", "cm", "mm"), default="m", help="a tet mesh file's coordinate unit (default m)")
    w.add_argument("--seconds", type=float, default=20.0, metavar="S", help="length of each run [s] (default 20)")
    w.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="servo rate [Hz] (default 1000)")
    w.add_argument("--fps", type=float, default=30.0, metavar="HZ", help="viewer update rate [Hz] (default 30)")
    w.add_argument("--realtime", action="store_true", help="every run's servo under SCHED_FIFO (palpate haptic --help)")
    w.add_argument("--json", action="store_true", help="one JSON object")
    w.set_defaults(func=cmd_bench_view)


def cmd_bench_view(a) -> int:
    if not (a.seconds >= 5 and math.isfinite(a.seconds)):
        raise Usage(f"palpate bench view: --seconds must be at least 5, got {a.seconds}")
    if not 250 <= a.rate <= 4000:
        raise Usage(f"palpate bench view: --rate must be within 250 to 4000 Hz, got {a.rate}")
    if not (1 <= a.fps <= 120):
        raise Usage(f"palpate bench view: --fps must be within 1 to 120, got {a.fps}")
    try:
        import viser  # noqa: F401
    except ImportError:
        raise RunFailed(f"palpate bench view: needs viser: {install_hint('view')}") from None
    from ..viewer.browser import find_chromium, have_playwright

    ok, why = have_playwright()
    exe, why2 = find_chromium()
    if not ok or exe is None:
        raise RunFailed(f"palpate bench view: needs a browser: {why or why2}")
    from ..bench import view as vb

    name, model = load_view_model(a.model, "bench view", a.unit)
    say = (lambda s: None) if a.json else (lambda s: print(f"  ... {s}", file=sys.stderr, flush=True))
    try:
        r = vb.bench(model, name, a.seconds, a.rate, a.fps, on_status=say, realtime=a.realtime)
    except palpate_errors() as e:
        raise Fail(f"palpate bench view: {type(e).__name__}: {e}", cause=e) from None
    if a.json:
        print(json.dumps(r), flush=True)
        return 0
    print(f"palpate {__version__} bench view: {name}, {a.rate:g} Hz, {a.seconds:g} s per run, hand dragged at 20 Hz "
          f"({r['cpu_count']} CPUs, load {r['load_avg_before']} -> {r['load_avg_after']}, {r['date']})")
    for label in ("alone", "viewer_no_page", "viewer", "alone_again"):
        x = r[label]
        print(f"  {label:<14} ticks {x['ticks']:>6}  {x['achieved_hz']:7.1f} Hz  period p50 {x['period_us_p50']:7.1f} "
              f"p99 {x['period_us_p99']:8.1f} max {x['period_us_max']:8.1f} us  overruns {x['overruns']}  "
              f"max force {x['max_force_n']:.3f} N")
    v = r["viewer"]
    print(f"  viewer: {v['viewer_frames_per_s']:.1f} frames/s pushed, page {v['page_animation_frames_per_s']:.1f} "
          f"animation frames/s, slowest frame {v['viewer_frame_ms_max']:.0f} ms; {v['browser_processes_niced']} browser "
          "processes niced")
    return 0


def _add_haptic(bsub) -> None:
    from ..bench import haptic as hb

    k = bsub.add_parser("haptic", help="the haptic loop's period, compute time and overruns on a scripted palpation",
                        description="Run the haptic servo loop on MODEL (a model file or shape name) for --seconds with a "
                                    "repeated scripted palpation, then the idle loop (no simulation) of the same length; "
                                    "report the period and compute-time percentiles and the overruns.")
    k.add_argument("model", metavar="MODEL")
    k.add_argument("--seconds", type=float, default=10.0, metavar="S", help="length of each run [s] (default 10)")
    k.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="servo rate [Hz] (default 1000)")
    add_physics_rate(k)
    k.add_argument("--no-idle", action="store_true", help="skip the idle-loop run")
    k.add_argument("--realtime", action="store_true",
                   help="run the servo under SCHED_FIFO (needs root, CAP_SYS_NICE or an rtprio limit; the report says "
                        "whether it was granted)")
    k.add_argument("--threads", type=int, default=1, metavar="N",
                   help="threads a tick's particle passes run on, 1 to 8 (default 1; see palpate haptic --help)")
    w = k.add_mutually_exclusive_group()
    w.add_argument("--busy-wait", action="store_true",
                   help="both runs' servo spins through each period instead of sleeping (the default without "
                        "--realtime; see palpate haptic --help)")
    w.add_argument("--sleep", action="store_true",
                   help="both runs' servo sleeps through each wait but its last 200 us (see palpate haptic --help)")
    k.add_argument("--json", action="store_true", help="one JSON object (keys: " + ", ".join(hb.BENCH_KEYS) + ", ...)")
    k.set_defaults(func=cmd_bench_haptic)


def cmd_bench_haptic(a) -> int:
    from ..bench import haptic as hb

    if not (a.seconds > 0 and math.isfinite(a.seconds)):
        raise Usage(f"palpate bench haptic: --seconds must be positive, got {a.seconds}")
    if not 250 <= a.rate <= 4000:
        raise Usage(f"palpate bench haptic: --rate must be within 250 to 4000 Hz, got {a.rate}")
    if not 1 <= a.threads <= 8:
        raise Usage(f"palpate bench haptic: --threads must be 1 to 8, got {a.threads}")
    hz = physics_rate(a, "bench haptic")
    if a.busy_wait and a.realtime:
        raise Usage("palpate bench haptic: --busy-wait and --realtime together: a real-time thread that never sleeps "
                    "meets the kernel's real-time throttling")
    name, model = load_hybrid_model(a.model, "bench haptic")
    try:
        r = hb.bench(model, a.seconds, a.rate, idle=not a.no_idle, name=name, realtime=a.realtime, threads=a.threads,
                          busy_wait=True if a.busy_wait else False if a.sleep else None, physics_rate=hz)
    except palpate_errors() as e:
        raise Fail(f"palpate bench haptic: {type(e).__name__}: {e}", cause=e) from None
    if a.json:
        print(json.dumps(r), flush=True)
    else:
        print(f"palpate {__version__} bench haptic: {name}, {a.rate:g} Hz for {a.seconds:g} s, scripted palpation "
              f"({r['cpu_count']} CPUs, load {r['load_avg']}, {r['date']}; servo scheduling: {r['realtime']}; "
              f"{r['threads']} thread{'s' if r['threads'] > 1 else ''}{'; busy-wait' if r['busy_wait'] else ''})")
        def row(label, x):
            print(f"  {label:<7} ticks {x['ticks']:>7}  {x['achieved_hz']:8.1f} Hz  period p50 {x['period_us_p50']:7.1f} "
                  f"p99 {x['period_us_p99']:8.1f} max {x['period_us_max']:8.1f} us  compute p99 {x['compute_us_p99']:8.1f} us "
                  f"(on the CPU {x['cpu_us_p99']:8.1f})  overruns {x['overruns']} (own {x['overruns_own']}, "
                  f"the machine's {x['overruns_machine']})")
        row("haptic", r)
        if "idle" in r:
            row("idle", r["idle"])
        p = r.get("physics")
        if p:
            print(f"  physics {p['ticks']:>7} ticks  {p['achieved_hz']:8.1f} Hz (of {p['rate_hz']:g})  compute p50 "
                  f"{p['compute_us_p50']:7.1f} p99 {p['compute_us_p99']:8.1f} us  lag p99 {p['lag_us_p99']:8.1f} max "
                  f"{p['lag_us_max']:8.1f} us  late {p['late']}  skipped {p['skipped']}  stale models {r['model_stalls']}")
        print(f"  max force {r['max_force_n']:.3f} N, largest force change in a servo period {r['max_force_step_n']:.4f} N "
              f"(in contact {r['max_force_step_contact_n']:.4f} N), "
              f"watchdog trips {r['watchdog_trips']}, faults {r['n_faults']}")
    return FAILED if r["n_faults"] else 0


def _bench_cases(a):
    from ..io import MeshError

    if a.all:
        if a.mesh:
            raise Usage("palpate bench protocol: give MESH or --all, not both")
        shared = bench.shared_dir()
        if shared is None:
            raise Fail("palpate bench protocol --all: shared bench meshes not found "
                       "(set PALPATE_SHARED to the folder holding bench/meshes)")
        paths = [shared / "bench" / "meshes" / f"lv_{m}.msh" for m in bench.MESHES]
        yield (lambda: bench.generated_case(a.force))
        for p in paths:
            yield (lambda p=p: bench.load_case(str(p), a.force))
        return
    if not a.mesh:
        raise Usage("palpate bench protocol: give a MESH file (.msh, .vtu, .npz) or --all")
    if a.mesh == bench.GENERATED:
        yield (lambda: bench.generated_case(a.force))
        return

    def one():
        try:
            return bench.load_case(a.mesh, a.force)
        except MeshError as e:
            raise Fail(f"palpate bench protocol: {e}") from None
    yield one


def cmd_bench_protocol(a) -> int:
    if not (math.isfinite(a.force) and a.force > 0):
        raise Usage(f"palpate bench protocol: --force must be a positive number of newtons, got {a.force}")
    if a.steps < 1:
        raise Usage("palpate bench protocol: --steps must be at least 1")
    newton = {"auto": None, "on": True, "off": False}[a.newton]
    if not a.json:
        print(f"palpate {__version__} bench protocol: {a.force:g} N, {a.steps} steps of {bench.DT * 1e3:g} ms, "
              f"integrator {a.integrator}, single thread (shared/bench/PROTOCOL.md)")
        print(f"{'mesh':<16}{'tets':>7}{'steps/s':>10}{'stable':>8}{'max|u| mm':>11}{'probe mm':>10}"
              f"{'iter':>6}{'inv':>5}{'p50 us':>8}{'p99 us':>8}{'max us':>8}{'vsStatic':>10}{'vsNewton':>10}")
    cases = list(_bench_cases(a))
    with _progress.task("bench protocol", total=len(cases), quiet=a.json) as advance:   # a terminal only
        for make in cases:
            _print_protocol_row(a, bench.run(make(), a.integrator, steps=a.steps, max_wall_s=a.max_wall, newton=newton))
            advance(1)
    return 0


def _print_protocol_row(a, r) -> None:
    """One result of bench.run: a JSON line or a table row."""
    if a.json:
        print(json.dumps(r), flush=True)
    else:
        def rel(k):
            return "-" if r[k] is None else f"{100 * r[k]:.3f}%"
        sps = "-" if r["steps_per_s"] is None else f"{r['steps_per_s']:.1f}"
        us = lambda k: "-" if r[k] is None else f"{r[k]:.0f}"  # noqa: E731
        it = "-" if r["iterations_mean"] is None else f"{r['iterations_mean']:.2f}"
        print(f"{r['mesh']:<16}{r['tets']:>7}{sps:>10}{str(r['stable']):>8}"
              f"{fmt_mm(r['max_disp_m']):>11}{fmt_mm(r['probe_disp_avg_m']):>10}{it:>6}"
              f"{r['inverted_max']:>5}{us('step_us_p50'):>8}{us('step_us_p99'):>8}{us('step_us_max'):>8}"
              f"{rel('rel_L2_vs_static'):>10}{rel('rel_L2_vs_newton'):>10}", flush=True)
        if r.get("error"):
            print(f"  note: {r['error']}")


def cmd_bench_particles(a) -> int:
    if a.all == (a.n is not None):
        raise Usage("palpate bench particles: give N or --all (not both)")
    if a.spacing <= 0 or a.spacing != a.spacing:
        raise Usage(f"palpate bench particles: --spacing must be positive, got {a.spacing}")
    if a.ticks <= 0:
        raise Usage("palpate bench particles: --ticks must be positive")
    if not (1.0 < a.support < 4.0):
        raise Usage(f"palpate bench particles: --support must lie between 1 and 4 spacings, got {a.support}")
    sizes = bp.ALL if a.all else [a.n]
    if not a.json:
        mhz = bp.cpu_mhz()
        peak = "unknown" if mhz is None else f"{mhz * bp.FLOPS_PER_CYCLE / 1e3:.1f} GFlop/s"
        print(f"palpate {__version__} bench particles: LV-shell cluster at {a.spacing * 1e3:g} mm, kernel {a.kernel}, "
              f"support {a.support:g} spacings, "
              f"E = {bp.E:g} Pa, nu = {bp.NU}, rho = {bp.RHO:g} kg/m^3, {bp.PROBE_FORCE:g} N on {bp.N_PROBE} particles, "
              f"{a.ticks} ticks of {bp.DT * 1e3:g} ms, one thread")
        print(f"  flops per pair per sub-step {bp.FLOPS_PER_PAIR}, per particle {bp.FLOPS_PER_PARTICLE}; peak {peak} "
              f"(cpu MHz {mhz} x {bp.FLOPS_PER_CYCLE} flop/cycle: AVX2 FMA, 2 units x 4 doubles x 2); "
              f"hot loop: {bp._p.simd_path()}")
        print(f"{'N':>7}{'in h':>6}{'nbrs':>7}{'fixed':>7}{'sub/tick':>9}{'sub dt us':>10}{'tick ms':>9}{'ticks/s':>9}"
              f"{'GFlop/s':>9}{'%peak':>7}{'build s':>9}{'max|u| mm':>10}")
    failed = False
    with _progress.task("bench particles", total=len(sizes), quiet=a.json or len(sizes) < 2) as advance:
        for n in sizes:
            failed |= _particles_row(a, n)
            advance(1)
    return FAILED if failed else 0


def _particles_row(a, n) -> bool:
    """One size of bench particles: run, print; whether it failed (not merely capped)."""
    try:
        r = bp.run(n, a.spacing, a.kernel, a.ticks, a.max_wall, a.support)
    except ValueError as e:
        raise Fail(f"palpate bench particles: {e}") from None
    except palpate_errors() as e:
        raise Fail(f"palpate bench particles: N = {n}: {type(e).__name__}: {e}", cause=e) from None
    failed = r["error"] is not None and "wall-clock cap" not in r["error"]
    if a.json:
        print(json.dumps(r), flush=True)
        return failed
    f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
    print(f"{r['n']:>7}{r['mean_neighbours_in_support']:>6.1f}{r['mean_neighbours']:>7.1f}{r['fixed']:>7}{r['substeps']:>9}{r['substep_dt_s'] * 1e6:>10.1f}"
          f"{f(r['tick_median_s'] and r['tick_median_s'] * 1e3, '.3f'):>9}{f(r['ticks_per_s'], '.1f'):>9}"
          f"{f(r['gflops'], '.2f'):>9}{f(r['peak_fraction'] and 100 * r['peak_fraction'], '.1f'):>7}"
          f"{r['build_s']:>9.2f}{fmt_mm(r['max_disp_m']):>10}", flush=True)
    if r["error"]:
        print(f"  note: {r['error']} (median over {r['ticks']} ticks)")
    return failed


def cmd_bench_hybrid(a) -> int:
    if a.active <= 0:
        raise Usage(f"palpate bench hybrid: --active must be a positive number of particles, got {a.active}")
    if a.ticks < bh.MIN_TICKS:
        raise Usage(f"palpate bench hybrid: --ticks must be at least {bh.MIN_TICKS}, got {a.ticks}")
    if a.radius is not None and not (a.radius > 0 and math.isfinite(a.radius)):
        raise Usage(f"palpate bench hybrid: --radius must be a positive number of metres, got {a.radius}")
    # The model's build and the calibration take seconds: a spinner on a terminal (the timed
    # ticks measure the step call alone).
    with _progress.task(f"bench hybrid {a.model}: building", quiet=a.json):
        name, model = load_hybrid_model(a.model, "bench hybrid")
    try:
        with _progress.task(f"bench hybrid {name}: calibrating and timing", quiet=a.json):
            r = bh.run(model, a.active, a.ticks, radius=a.radius, name=name, mass_scaling=a.mass_scaling,
                       tool_area_stiffness=a.tool_area_stiffness, implicit_exchange=not a.explicit_exchange)
    except ValueError as e:
        raise Fail(f"palpate bench hybrid: {e}") from None
    except palpate_errors() as e:
        raise Fail(f"palpate bench hybrid: {type(e).__name__}: {e}", cause=e) from None
    if a.json:
        print(json.dumps(r), flush=True)
    else:
        f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
        print(f"palpate {__version__} bench hybrid: {r['model']} ({r['core_tets']} core tets, {r['particles']} particles, "
              f"{r['regions']} regions), E = {bh.E:g} Pa, nu = {bh.NU}, rho = {bh.RHO:g} kg/m^3, paper damping; "
              f"{r['ticks_planned']} ticks of {bh.DT * 1e3:g} ms: press {bh.DEPTH * 1e3:g} mm, hold, slide "
              f"{bh.SLIDE * 1e3:g} mm, release; one thread")
        print(f"  {r['cpu_count']} CPUs ({r['cpu_model']}), python {r['python_version']}, {r['date']}")
        exchange = "implicit exchange" if r["implicit_exchange"] else "explicit exchange, capped"
        print(f"  the shell's coupling springs {r['coupling_stiffness']:.3g} N/m ({exchange})")
        cal = ", ".join(f"{rr * 1e3:.3f} mm: {cc}" for rr, cc in r["calibration"])
        print(f"  calibration ({r['calibration_s']:.1f} s; tool radius: active at the held press): {cal}")
        print(f"{'target':>7}{'radius mm':>10}{'at press':>9}{'mean':>8}{'max':>6}{'ticks':>7}{'mean ms':>9}"
              f"{'p50 ms':>8}{'p99 ms':>8}{'max ms':>8}{'ticks/s':>9}{'stable':>8}{'max F N':>9}")
        print(f"{r['active_target']:>7}{r['tool_radius_m'] * 1e3:>10.3f}{r['active_particles_calibrated']:>9}"
              f"{f(r['active_particles_mean'], '.1f'):>8}{f(r['active_particles_max'], 'd'):>6}{r['ticks']:>7}"
              f"{f(r['tick_ms_mean'], '.3f'):>9}{f(r['tick_ms_p50'], '.3f'):>8}{f(r['tick_ms_p99'], '.3f'):>8}"
              f"{f(r['tick_ms_max'], '.3f'):>8}{f(r['ticks_per_s'], '.0f'):>9}{str(r['stable']):>8}"
              f"{r['max_force_n']:>9.4f}", flush=True)
        print(f"  time to the force (the tick's part before a servo sends it): mean {f(r['force_ms_mean'], '.3f')} ms, "
              f"p50 {f(r['force_ms_p50'], '.3f')}, p99 {f(r['force_ms_p99'], '.3f')}, max {f(r['force_ms_max'], '.3f')}", flush=True)
    if not r["stable"]:
        print(f"palpate: error: palpate bench hybrid: tick {r['failed_tick']} ({r['failed_phase']}) failed: "
              f"{r['error']}", file=sys.stderr)
        return FAILED
    return 0
