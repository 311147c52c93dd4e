"""Running a study on Dask ``distributed``: the model goes to every worker once
(a task every scenario depends on), scenarios run as tasks (short ones a few to a task:
:func:`batch_size`), and rows reach the table as they finish.

Where it runs (:func:`sweep`): ``client=`` an existing ``distributed.Client`` (a cluster of any
size, unchanged code); ``scheduler="tcp://host:8786"`` connects to one; otherwise a
``LocalCluster`` of single-threaded worker processes, one per core (``workers=N`` to choose;
``workers=0`` runs the scenarios one after the other in this process, without Dask: the
reference the tests compare the cluster's table with).

Output folder (``out``):
- ``results.parquet``: the table, one row per scenario in the study's order (written at the end;
  see :mod:`palpate.sweep.scenario` for the columns);
- ``results.csv``: the same rows without the curves, for a spreadsheet or a reader without
  pyarrow or pandas;
- ``results.png``: the plot (:mod:`palpate.sweep.plot`: the scenarios' force-depth curves, or
  without curves the main outcome against the first varied parameter); needs matplotlib (the
  ``plot`` extra): without it, no plot and a note on stderr;
- ``parts/part-NNNNNN.parquet``: the rows as they finished, a part every few seconds (what
  ``resume`` reads back: a killed study keeps everything up to its last part);
- ``fields/NNNNNNN.npy``: the final displacement fields (``outputs.field``), (n, 3) [m];
- ``manifest.json``: palpate's version, the spec (as given, and its digest), the model's hash,
  the seed, the scenario count, and the state (``running`` | ``complete``).

The table does not depend on the number of workers or the order in which tasks finish, except for
the timing column ``wall_s``. A lost worker's task is re-run by the scheduler (up to
``distributed.scheduler.allowed-failures``, 3 by default); past that, its row says so.
"""
from __future__ import annotations

import collections
import contextlib
import hashlib
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Union

import numpy as np

from .. import _palpate as _p
from .. import __version__
from .._extras import install_hint
from .scenario import FIELD, Payload, finite_or_none, run_scenario, save_field
from .spec import TEXT, WHOLE, Spec, SweepSpecError, load_spec, spec_from_dict

#: A part is written when this many rows are waiting or PART_SECONDS have passed.
PART_ROWS = 256
PART_SECONDS = 5.0

#: Numeric outcome columns (float) and whole ones (int), in the table's order after the parameters.
FLOAT_COLS = ("max_force_n", "final_depth_m", "max_disp_m", "strain_energy_j", "kinetic_energy_j", "iterations_mean", "wall_s")
INT_COLS = ("steps_done", "iterations_max")
CURVE_COLS = ("curve_time_s", "curve_force_n", "curve_depth_m")


class SweepError(_p.PalpateError, RuntimeError):
    """A study that cannot go on (its output folder holds another study, the cluster is gone)."""


@dataclass
class StudyResult:
    """What :func:`sweep` returns: the table (a ``pyarrow.Table``; ``.to_pandas()`` with pandas
    installed), its path, the manifest, and the counts."""
    table: Any
    path: Path
    manifest: Dict[str, Any]
    done: int
    failed: int
    ran: int          # scenarios run by this call (a resumed study skips the finished ones)
    plot: Optional[Path] = None   # results.png (None: not asked for, or no matplotlib)

    def rows(self) -> List[Dict[str, Any]]:
        return self.table.to_pylist()


def schema(spec: Spec):
    """The table's Arrow schema for ``spec``: scenario, parameters, status, outcomes, curves."""
    import pyarrow as pa
    fields = [pa.field("scenario", pa.int64())]
    for k in spec.loading:
        fields.append(pa.field(k, pa.string() if k in TEXT else pa.int64() if k in WHOLE else pa.float64()))
    fields += [pa.field("status", pa.string()), pa.field("error", pa.string()), pa.field("stable", pa.bool_())]
    fields += [pa.field(c, pa.float64()) for c in FLOAT_COLS]
    fields += [pa.field(c, pa.int64()) for c in INT_COLS]
    if spec.curve:
        fields += [pa.field(c, pa.list_(pa.float64())) for c in CURVE_COLS]
    return pa.schema(fields)


def model_payload(spec: Spec) -> Payload:
    """Load (or build) the study's model once, in the driver."""
    if spec.kind == "probe":
        from .. import bench
        from ..io import read_mesh_arrays
        v = spec.model["mesh"]
        if v == bench.GENERATED:
            m = bench.generated_case()
            return Payload("probe", v, mesh=m.mesh, points_mu=np.asarray(m.mesh.points) / bench.SCALE, tets=np.asarray(m.mesh.tets))
        if v in bench.MESHES or v.startswith("lv_"):
            short = v[3:] if v.startswith("lv_") else v
            path = bench.bench_mesh_path(short)
            if path is None:
                raise SweepSpecError(f"model.mesh: the shared bench mesh lv_{short} is not here (no ../shared/bench/meshes; "
                                     "set PALPATE_SHARED)")
            v = str(path)
        points, tets, _, _ = read_mesh_arrays(v, unit="m")   # raw mesh units
        points = np.asarray(points, dtype=np.float64)
        case = bench.setup(Path(v).stem, points, tets)      # checks it is a protocol ventricle
        return Payload("probe", Path(v).stem, mesh=case.mesh, points_mu=points, tets=np.asarray(tets))
    from ..hybrid import load_model
    name, model = load_model(spec.model["hybrid"])
    script = None
    if spec.script is not None:
        from ..touch import parse_script
        script = parse_script(spec.script)
    return Payload("press", name, hybrid=model, script=script)


def model_hash(payload: Payload) -> str:
    h = hashlib.sha256()
    if payload.kind == "probe":
        h.update(np.ascontiguousarray(payload.points_mu, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(payload.tets, dtype=np.int64).tobytes())
    else:
        h.update(payload.hybrid.to_bytes())
    return h.hexdigest()[:16]


class _Table:
    """The output folder: parts written as rows arrive, the manifest, the final table."""

    def __init__(self, out: Path, spec: Spec, manifest: Dict[str, Any]):
        self.out, self.spec, self.schema = out, spec, schema(spec)
        self.parts = out / "parts"
        self.parts.mkdir(parents=True, exist_ok=True)
        self.pending: List[Dict[str, Any]] = []
        self.last_flush = time.monotonic()
        self.manifest = manifest
        self.seq = 1 + max((int(p.stem.split("-")[1]) for p in self.parts.glob("part-*.parquet")), default=-1)

    def finished(self) -> Dict[int, str]:
        """Scenario -> status of the rows already in parts (a resumed study skips them)."""
        import pyarrow.parquet as pq
        out: Dict[int, str] = {}
        for p in sorted(self.parts.glob("part-*.parquet")):
            try:
                t = pq.read_table(p, columns=["scenario", "status"])
            except Exception as e:  # noqa: BLE001 - a torn part (killed while writing) is redone
                print(f"palpate sweep: warning: {p} is unreadable ({type(e).__name__}); its scenarios run again", file=sys.stderr)
                p.unlink()
                continue
            for s, st in zip(t.column("scenario").to_pylist(), t.column("status").to_pylist()):
                out[int(s)] = st
        return out

    def add(self, row: Dict[str, Any]) -> None:
        self.pending.append(row)
        if len(self.pending) >= PART_ROWS or time.monotonic() - self.last_flush >= PART_SECONDS:
            self.flush()

    def flush(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq
        self.last_flush = time.monotonic()
        if not self.pending:
            return
        t = pa.Table.from_pylist([{k: _cell(r.get(k)) for k in self.schema.names} for r in self.pending], schema=self.schema)
        path = self.parts / f"part-{self.seq:06d}.parquet"
        tmp = path.with_suffix(".tmp")
        pq.write_table(t, tmp)
        os.replace(tmp, path)   # a part is there whole or not at all
        self.seq += 1
        self.pending.clear()

    def write_manifest(self, **update: Any) -> None:
        self.manifest.update(update)
        tmp = self.out / "manifest.json.tmp"
        tmp.write_text(json.dumps(self.manifest, indent=2, default=str))
        os.replace(tmp, self.out / "manifest.json")

    def finish(self):
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.parquet as pq
        self.flush()
        parts = [pq.read_table(p, schema=self.schema) for p in sorted(self.parts.glob("part-*.parquet"))]
        t = pa.concat_tables(parts) if parts else self.schema.empty_table()
        # One row per scenario (the last written, should a scenario have been written twice),
        # in the study's order.
        last = {s: i for i, s in enumerate(t.column("scenario").to_pylist())}
        t = t.take(pa.array([last[s] for s in sorted(last)], type=pa.int64()))
        path = self.out / "results.parquet"
        tmp = path.with_suffix(".tmp")
        pq.write_table(t, tmp)
        os.replace(tmp, path)
        import pyarrow.csv as pcsv
        flat = t.drop_columns([c for c in CURVE_COLS if c in t.column_names])
        tmp_csv = self.out / "results.csv.tmp"
        pcsv.write_csv(flat, tmp_csv)
        os.replace(tmp_csv, self.out / "results.csv")
        failed = int(pc.sum(pc.equal(t.column("status"), "failed")).as_py() or 0) if t.num_rows else 0
        return t, path, failed


def _cell(v: Any) -> Any:
    if isinstance(v, (np.floating, np.integer)):
        v = v.item()
    return finite_or_none(v)


def sweep(spec: Union[Spec, Dict[str, Any], str, os.PathLike], out: Union[str, os.PathLike, None] = None, *,
          client: Any = None, scheduler: Optional[str] = None, workers: Optional[int] = None, resume: bool = False,
          quiet: bool = False, log: Optional[Callable[[str], None]] = None, plot: bool = True) -> StudyResult:
    """Run the study ``spec`` (a :class:`Spec`, its dict, or the path of its TOML file) and write
    its table to ``out`` (default ``sweep-<name>`` in the current folder). See the module docs
    for where it runs; ``resume``: continue the study already in ``out`` (same spec), running only
    the scenarios without a row; without it, an ``out`` that holds a study is refused. ``log``
    gets one-line messages (the dashboard's address, the summary); a progress bar shows on a
    terminal unless ``quiet``. ``plot``: draw ``results.png`` beside the table
    (:mod:`palpate.sweep.plot`; without matplotlib, none and a note on stderr). Raises :class:`SweepSpecError` for a bad spec, :class:`SweepError`
    for an output folder that holds another study."""
    if isinstance(spec, Spec):
        sp = spec
    elif isinstance(spec, dict):
        sp = spec_from_dict(spec)
    else:
        sp = load_spec(spec)
    out_dir = Path(out) if out is not None else Path(f"sweep-{sp.name}")
    say = log or (lambda s: None)
    _check_workers(workers)
    mpath = out_dir / "manifest.json"
    old: Optional[Dict[str, Any]] = None
    if out_dir.exists() and not out_dir.is_dir():
        raise SweepError(f"{out_dir}: exists and is not a folder")
    if mpath.exists():
        try:
            old = json.loads(mpath.read_text())
        except (OSError, ValueError) as e:
            raise SweepError(f"{mpath}: unreadable manifest ({e}): remove the folder or give another --out") from None
        if not resume:
            raise SweepError(f"{out_dir}: holds a study already ({old.get('study')!r}, {old.get('state')}): "
                             "--resume continues it, or give another --out")
        if old.get("spec_digest") != sp.digest():
            raise SweepError(f"{out_dir}: holds another study (spec digest {old.get('spec_digest')}, this one's "
                             f"{sp.digest()}): resume needs the same spec")
    elif out_dir.exists() and any(out_dir.iterdir()):
        raise SweepError(f"{out_dir}: a folder that is not empty and holds no study: give another --out")

    payload = model_payload(sp)
    mhash = model_hash(payload)
    scenarios = sp.scenarios()
    manifest = {"palpate_version": __version__, "study": sp.name, "spec_digest": sp.digest(), "spec": sp.source,
                "model": sp.model, "model_hash": mhash, "script": sp.script, "seed": sp.seed, "scenarios": len(scenarios),
                "varied": sp.varied(), "state": "running", "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    if old is not None:
        if old.get("model_hash") != mhash:
            raise SweepError(f"{out_dir}: its study ran on another model (hash {old.get('model_hash')}, now {mhash})")
        manifest["started"] = old.get("started", manifest["started"])
    out_dir.mkdir(parents=True, exist_ok=True)
    table = _Table(out_dir, sp, manifest)
    done_before = table.finished() if resume else {}
    todo = [s for s in scenarios if s["scenario"] not in done_before]
    table.write_manifest()
    field_dir = str(out_dir / "fields") if sp.field else None
    if resume:
        say(f"palpate sweep: {sp.name}: {len(done_before)} of {len(scenarios)} scenarios already done, {len(todo)} to run")

    from .. import _progress
    failed = sum(1 for st in done_before.values() if st == "failed")
    with _progress.task(f"sweep {sp.name}", total=len(scenarios), quiet=quiet, eta=True) as advance:
        advance(len(done_before))

        def got(s: Dict[str, Any], row: Dict[str, Any]) -> None:
            nonlocal failed
            u = row.pop(FIELD, None)
            if u is not None and field_dir is not None:
                save_field(field_dir, s["scenario"], u)
            full = dict(s)
            full.update(row)
            table.add(full)
            failed += row["status"] == "failed"
            advance(1, f"sweep {sp.name} ({failed} failed)" if failed else None)

        with Runner(payload, client=client, scheduler=scheduler, workers=workers, log=say) as runner:
            runner.run(todo, got, curve=sp.curve, field=sp.field)
    t, path, n_failed = table.finish()
    table.write_manifest(state="complete", finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"), done=t.num_rows, failed=n_failed)
    png = _plot(t, out_dir / "results.png", sp) if plot else None
    say(f"palpate sweep: {sp.name}: {t.num_rows} scenarios ({n_failed} failed) in {path}")
    return StudyResult(table=t, path=path, manifest=table.manifest, done=t.num_rows, failed=n_failed, ran=len(todo),
                       plot=png)


def _plot(t: Any, path: Path, sp: Spec) -> Optional[Path]:
    """The study's plot at ``path``, or None (and a note on stderr) without matplotlib: the table
    stands without it."""
    from .plot import plot_study
    try:
        return plot_study(t, path, name=sp.name, kind=sp.kind, varied=sp.varied())
    except ImportError:   # matplotlib is an extra (palpate[plot])
        print(f"(matplotlib not installed: no {path.name}; {install_hint('plot')})", file=sys.stderr)
        return None


class Runner:
    """Where scenarios run, shared by :func:`sweep` and :func:`palpate.sweep.fit.fit`: in this
    process (``workers=0``), on ``client``, on the scheduler at ``scheduler``, or on a
    ``LocalCluster`` of ``workers`` single-threaded processes (default: one per core) that it
    starts and, on leaving the ``with`` block, stops. The payload (the model) is sent to every
    worker once, when the first scenarios are submitted."""

    def __init__(self, payload: Payload, *, client: Any = None, scheduler: Optional[str] = None,
                 workers: Optional[int] = None, log: Optional[Callable[[str], None]] = None):
        _check_workers(workers)
        self.payload, self.client, self.say = payload, client, log or (lambda s: None)
        self.local = workers == 0 and client is None and scheduler is None
        self._own: List[Any] = []
        self._model = None
        if self.local:
            return
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise SweepError(f"palpate sweep runs on Dask: {install_hint('study')}, "
                             "or run in this process with workers=0 (--workers 0)") from None
        if self.client is None:
            if scheduler is not None:
                try:
                    self.client = Client(scheduler, timeout="10s")
                except (OSError, TimeoutError) as e:
                    raise SweepError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
            else:
                n = workers or os.cpu_count() or 1
                with _local_cluster_settings():
                    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           dashboard_address=_dashboard())
                self._own.append(cluster)
                self.client = Client(cluster)
            self._own.insert(0, self.client)
            link = getattr(self.client, "dashboard_link", None)
            if link and (scheduler is not None or _dashboard() is not None):
                self.say(f"palpate sweep: Dask dashboard at {link}")

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        for o in self._own:
            try:
                o.close()
            except Exception:  # noqa: BLE001 - closing a cluster that is already gone
                pass
        self._own.clear()

    def run(self, scenarios: Sequence[Dict[str, Any]], on_row: Callable[[Dict[str, Any], Dict[str, Any]], None], *,
            curve: bool = True, field: bool = False) -> None:
        """Run ``scenarios``, calling ``on_row(scenario, row)`` as each finishes (any order)."""
        if self.local:
            for s in scenarios:
                on_row(s, run_scenario(self.payload, s, curve, field))
            return
        from distributed import as_completed
        client = self.client
        if self._model is None:
            # The model once to every worker, not once a task: a task of its own that every
            # scenario depends on, so each worker fetches (and unpickles) it once and keeps it.
            # Not `Client.scatter`: scattered data lost with a worker cannot be recomputed, and
            # the study would stop; a task's result is recomputed from its (scheduler-held) input.
            self._model = client.submit(_model_task, self.payload, pure=False, key=f"palpate-model-{time.monotonic_ns()}")
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        window = 4 * n_workers   # tasks in flight: a million-scenario study is not a million futures
        todo = list(scenarios)
        nxt = 0
        # The scenario times the batch size is taken from: the most recent ones (a median over a
        # whole million-scenario study at every submission would be quadratic).
        walls: "collections.deque[float]" = collections.deque(maxlen=RECENT_WALLS)
        by_key: Dict[str, List[Dict[str, Any]]] = {}

        def submit():
            nonlocal nxt
            b = batch_size(walls, len(todo) - nxt, n_workers)
            batch = todo[nxt:nxt + b]
            nxt += len(batch)
            f = client.submit(run_batch, self._model, batch, curve, field, pure=False,
                              key=f"palpate-scenarios-{batch[0]['scenario']}-{len(batch)}-{time.monotonic_ns()}")
            by_key[f.key] = batch
            return f

        ac = as_completed([submit() for _ in range(window) if nxt < len(todo)])
        for fut in ac:
            batch = by_key.pop(fut.key)
            try:
                rows = fut.result()
            except Exception as e:  # noqa: BLE001 - KilledWorker (lost too often), a cancelled task
                rows = [{"status": "failed", "error": f"{type(e).__name__}: {e} (the task's worker was lost)"} for _ in batch]
            for s, row in zip(batch, rows):
                if row.get("status") == "ok":
                    walls.append(float(row.get("wall_s") or 0.0))
                on_row(s, row)
            if nxt < len(todo):
                ac.add(submit())

    def map(self, scenarios: Sequence[Dict[str, Any]], *, curve: bool = True) -> List[Dict[str, Any]]:
        """The rows of ``scenarios`` (parameters and outcomes), in their order."""
        rows: Dict[int, Dict[str, Any]] = {}

        def got(s: Dict[str, Any], row: Dict[str, Any]) -> None:
            full = dict(s)
            full.update(row)
            rows[id(s)] = full
        self.run(scenarios, got, curve=curve)
        return [rows[id(s)] for s in scenarios]


#: A task runs scenarios for about this long [s] once their time is known: on 2 cores the
#: driver's own work per task (scheduling, messages, results: ~5-7 ms) competes with the workers
#: (BENCHMARKS.md, issue 17), so short scenarios go in batches.
TASK_SECONDS = 1.0
#: How many of the latest scenario times that median is taken over.
RECENT_WALLS = 64


def batch_size(walls: Sequence[float], remaining: int, n_workers: int) -> int:
    """Scenarios in the next task: one until a scenario has finished; then as many as fill
    :data:`TASK_SECONDS` at the median of ``walls`` (the latest scenario times), but never so many that a worker
    would get fewer than four of the remaining tasks (the study's tail stays balanced)."""
    if remaining <= 0:
        return 0
    if not walls:
        return 1
    med = float(np.median(walls))
    fill = int(TASK_SECONDS / med) if med > 0 else remaining
    return max(1, min(fill, remaining // (4 * n_workers)))


def run_batch(payload: Payload, batch: Sequence[Dict[str, Any]], curve: bool, field: bool) -> List[Dict[str, Any]]:
    """The rows of ``batch``, in its order (a task of :meth:`Runner.run`)."""
    return [run_scenario(payload, s, curve, field) for s in batch]


def _model_task(payload: Payload) -> Payload:
    return payload


def _check_workers(workers: Any) -> None:
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 0):
        raise _p.ParameterError(f"workers = {workers!r} must be a whole number, 0 or more (0: in this process)")


#: Dask settings of the LocalCluster a study starts (a cluster passed in or reached with
#: ``--scheduler`` keeps its own): every periodic task these turn down runs in a process that
#: shares the cores with the scenarios, which on a 2-core machine is the 2-worker run's loss.
#: Measured with ``palpate bench sweep`` (lv_1350, 64 scenarios, medians of 5, quiet machine):
#: 2 workers 3.69 s -> 3.57 s (speed-up over 1 worker 1.72x -> 1.77x); 1 worker unchanged.
LOCAL_CLUSTER_CONFIG = {
    # The workers' statistical profiler (the dashboard's "Profile" page) samples every 10 ms.
    "distributed.worker.profile.enabled": False,
    # The event loops' blocked-loop watchdog and the nannies' memory watch: seconds, not 20 ms
    # and 100 ms (a scenario holds a model and a curve, megabytes).
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    # Scenarios are alike and the runner keeps a short queue: nothing to steal.
    "distributed.scheduler.work-stealing": False,
}


@contextlib.contextmanager
def _local_cluster_settings() -> Iterator[None]:
    """The LocalCluster's settings (:data:`LOCAL_CLUSTER_CONFIG`), and its worker processes
    started by ``fork`` on Linux unless the user chose a method
    (``distributed.worker.multiprocessing-method`` in Dask's config): a forked worker inherits the
    imported numpy, Dask and palpate instead of importing them again, which took the cluster's
    start and stop from 0.8 s to 0.2 s here (2 workers), a cost every study pays. Dask supports
    fork, and a forked worker runs only Dask's worker and palpate's scenarios (the core keeps no
    threads or locks of its own). Elsewhere (macOS, Windows) Dask's default (spawn) is kept."""
    import dask
    config: Dict[str, Any] = dict(LOCAL_CLUSTER_CONFIG)
    user_set = dask.config.get("distributed.worker.multiprocessing-method", None) != "spawn"
    if sys.platform == "linux" and not user_set and not os.environ.get("DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD"):
        config["distributed.worker.multiprocessing-method"] = "fork"
    with dask.config.set(config):
        yield


def _dashboard() -> Optional[str]:
    """The LocalCluster's dashboard address: a free port on loopback when bokeh (the dashboard's
    dependency) is installed, else none."""
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return None
    return "127.0.0.1:0"
