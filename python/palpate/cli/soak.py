"""``palpate soak MODEL --minutes N``: the haptic loop under a random scripted palpation for N
minutes (:func:`palpate.haptics.random_palpation`), reporting the rate, overruns, the largest
force, the energy the device put into the user (its drift: a passive loop keeps it at or below
zero once past the ramp) and any error."""
from __future__ import annotations

import json
import math
import sys

from ._common import FAILED, Fail, Usage, add_physics_rate, load_hybrid_model, palpate_errors, physics_rate


def add_parser(sub) -> None:
    s = sub.add_parser("soak", help="run the haptic loop on a random scripted palpation for N minutes",
                       description="Soak test: the haptic servo loop on MODEL under a random scripted palpation.")
    s.add_argument("model", metavar="MODEL")
    s.add_argument("--minutes", type=float, required=True, metavar="N")
    s.add_argument("--rate", type=float, default=1000.0, metavar="HZ", help="servo rate [Hz] (default 1000)")
    s.add_argument("--seed", type=int, default=0, help="random seed of the palpation (default 0)")
    s.add_argument("--json", action="store_true", help="the report as one JSON object")
    s.add_argument("--realtime", action="store_true", help="run the servo under SCHED_FIFO (see palpate haptic --help)")
    add_physics_rate(s)
    s.set_defaults(func=cmd_soak)


def cmd_soak(a) -> int:
    from .. import _palpate as _p
    from .. import haptics

    if not (a.minutes > 0 and math.isfinite(a.minutes)):
        raise Usage(f"palpate soak: --minutes must be positive, got {a.minutes}")
    if not 250 <= a.rate <= 4000:
        raise Usage(f"palpate soak: --rate must be within 250 to 4000 Hz, got {a.rate}")
    hz = physics_rate(a, "soak")
    name, model = load_hybrid_model(a.model, "soak")
    seconds = 60.0 * a.minutes
    t, k = haptics.random_palpation(model, seconds + 1.0, seed=a.seed)
    try:
        loop = _p.HapticLoop(model, haptics.material(), "scripted", times=t, knots=k, rate_hz=a.rate,
                             max_ticks=int(round(seconds * a.rate)), realtime=a.realtime, **haptics.loop_rates(hz))
    except palpate_errors() as e:
        raise Fail(f"palpate soak: {type(e).__name__}: {e}", cause=e) from None
    show = None if a.json else (lambda line: print(line, flush=True))
    r = haptics.run_live(loop, None, show, every=5.0)
    r["model"], r["minutes"], r["seed"] = name, a.minutes, a.seed
    if a.json:
        print(json.dumps(r))
    else:
        print(f"palpate soak: {name}, {a.minutes:g} min at {a.rate:g} Hz (seed {a.seed}): {r['ticks']} ticks, "
              f"{r['achieved_hz']:.1f} Hz achieved; period p99 {r['period_us_p99']:.0f} us, max {r['period_us_max']:.0f} us; "
              f"overruns {r['overruns']} (own {r['overruns_own']}, the machine's {r['overruns_machine']}); max force {r['max_force_n']:.3f} N; energy into the user "
              f"{r['energy_into_user_j']:.3e} J; faults {r['n_faults']}")
        for f in r["faults"][:10]:
            what = "fault" if f.get("fault", True) else "event"
            print(f"  {what} at tick {f['tick']} (t = {f['time']:.3f} s): {f['reason']}", file=sys.stderr)
    return FAILED if r["n_faults"] else 0
