"""Parameter sweeps: many runs of one scene, each as ``augmpm run`` makes it, on a Dask cluster.

A sweep is described by a TOML file (SPEC)::

    scene = "dam_break"        # the base scene: a file (relative to SPEC) or a shipped scene's name
    steps = 400                # optional: every run's steps (as `augmpm run --steps`)
    set = ["grid.resolution=32"]   # optional: overrides of every run (as `augmpm run --set`)
    render = false             # optional: PNG frames and an animation for each run (default false)
    checkpoint_every = 1       # optional: output frames between a run's checkpoints (default 1)
    samples = 4                # random samples, with [random] (default 1)
    seed = 0                   # the random samples' seed (default 0)

    [grid]                     # every combination of these values (any scene key, method, precision)
    "bodies[0].material.viscosity" = [0.1, 1.0]
    method = ["naive", "augmented"]

    [random]                   # each run of the grid, `samples` times with values drawn from these
    "bodies[0].material.stiffness" = { uniform = [1.0e4, 4.0e4] }
    "gravity[1]" = { log_uniform = [-20.0, -5.0] }  # by the logarithm of its size (same sign at both ends)
    "time.cfl" = { choice = [0.2, 0.25] }
    "seed" = { integers = [0, 1000] }               # integers, both ends included

    [plot]                     # sweep.png: this metric against this parameter (defaults: the first
    metric = "max_penetration" # metric below, the first varied key)
    parameter = "bodies[0].material.viscosity"

Runs are numbered in that order (the grid's last key fastest, then the samples) and written to
``DIR/runs/run_00000/`` exactly as ``augmpm run`` writes them, bitwise the same as the same scene run
alone. A finished run keeps ``summary.json`` and is never run again: running the sweep again resumes it.
A run whose worker died restarts from its last checkpoint on another worker. ``DIR/sweep.csv`` and
``DIR/sweep.parquet`` hold every run's parameters and :data:`SUMMARY_COLUMNS`; ``DIR/sweep.png`` plots one
metric against one parameter.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import math
import os
import time as wallclock
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from augmpm import _core
from augmpm.files import output_dir, save_png, write_bytes, write_text
from augmpm.scene import _plain_error, load_scene, scene_path
from augmpm.simulation import available_cores

#: What the sweep reports of each run after its parameters: ``status`` (``ok``; ``failed``: the simulation
#: went bad, ``error`` says at which step and why; ``error``: the run could not be completed, and will be
#: tried again by the next call), the most particles outside the walls in any frame, the deepest a particle
#: was past a wall in any frame (cells), the kinetic energy at the last frame (J, per metre of depth in 2D),
#: the wall time of the attempt that finished it (s), its attempts, and its directory.
SUMMARY_COLUMNS = [
    "status",
    "max_n_outside",
    "max_penetration",
    "final_kinetic_energy",
    "run_time",
    "attempts",
    "frames",
    "error",
    "dir",
]
#: The metrics ``[plot] metric`` may name, with their units.
PLOT_METRICS = ["max_n_outside", "max_penetration", "final_kinetic_energy", "run_time"]
_UNITS = {"max_n_outside": "particles", "max_penetration": "cells h", "final_kinetic_energy": "J", "run_time": "s"}
SUMMARY = "summary.json"
_ATTEMPTS = "attempts.log"
_SPEC_KEYS = {"scene", "steps", "set", "render", "checkpoint_every", "samples", "seed", "grid", "random", "plot"}
_DISTRIBUTIONS = ("uniform", "log_uniform", "choice", "integers")


@dataclass
class SweepSpec:
    """A sweep, read from SPEC by :func:`load_spec`."""

    scene: Path
    steps: int | None = None
    overrides: list[str] = field(default_factory=list)
    render: bool = False
    checkpoint_every: int = 1
    samples: int = 1
    seed: int = 0
    grid: dict[str, list[Any]] = field(default_factory=dict)
    random: dict[str, tuple[str, list[Any]]] = field(default_factory=dict)
    plot_metric: str = PLOT_METRICS[1]
    plot_parameter: str | None = None

    @property
    def keys(self) -> list[str]:
        """The varied scene keys: the grid's, then the random ones."""
        return [*self.grid, *self.random]

    def runs(self) -> list[dict[str, Any]]:
        """Each run's values of the varied keys, in run order; the same for the same SPEC."""
        rng = np.random.default_rng(self.seed)
        points = list(itertools.product(*self.grid.values())) if self.grid else [()]
        runs = []
        for point in points:
            for _ in range(self.samples if self.random else 1):
                values = dict(zip(self.grid, point, strict=True))
                for key, (kind, args) in self.random.items():
                    values[key] = _draw(rng, kind, args)
                runs.append(values)
        return runs


def _draw(rng: np.random.Generator, kind: str, args: list[Any]) -> Any:
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    if kind == "log_uniform":
        sign = math.copysign(1.0, args[0])
        low, high = sorted((math.log(abs(args[0])), math.log(abs(args[1]))))
        return sign * float(math.exp(rng.uniform(low, high)))
    if kind == "integers":
        return int(rng.integers(args[0], args[1], endpoint=True))
    return args[int(rng.integers(len(args)))]


def load_spec(path: str | Path) -> SweepSpec:
    """Reads and checks a sweep SPEC; bad input raises :class:`augmpm.SceneError` naming the key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise _plain_error(str(path), f"cannot read sweep spec ({e.strerror})") from None
    except UnicodeDecodeError as e:
        raise _plain_error(str(path), f"sweep spec is not UTF-8 text ({e.reason})") from None
    except tomllib.TOMLDecodeError as e:
        raise _plain_error(str(path), f"not valid TOML: {e}") from None
    unknown = sorted(set(data) - _SPEC_KEYS)
    if unknown:
        raise _plain_error(unknown[0], f"not a sweep key (expected one of {', '.join(sorted(_SPEC_KEYS))})")
    if not isinstance(data.get("scene"), str):
        raise _plain_error("scene", "required: the base scene's file (relative to the spec) or shipped name")
    scene = Path(data["scene"])
    scene = path.parent / scene if not scene.is_absolute() and (path.parent / scene).exists() else scene
    spec = SweepSpec(scene=scene_path(scene))

    def integer(key: str, low: int) -> int | None:
        value = data.get(key)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool) or value < low):
            raise _plain_error(key, f"must be an integer ≥ {low}, got {value!r}")
        return value

    spec.steps = integer("steps", 0)
    spec.checkpoint_every = _default(integer("checkpoint_every", 0), 1)
    spec.samples = _default(integer("samples", 1), 1)
    spec.seed = _default(integer("seed", 0), 0)
    overrides = data.get("set", [])
    if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
        raise _plain_error("set", "must be a list of KEY=VALUE strings")
    spec.overrides = overrides
    if not isinstance(data.get("render", False), bool):
        raise _plain_error("render", f"must be true or false, got {data['render']!r}")
    spec.render = data.get("render", False)
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise _plain_error("grid", "must be a table of scene keys and lists of values")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise _plain_error(f"grid.{key}", f"must be a non-empty list of values, got {values!r}")
        spec.grid[key] = values
    random = data.get("random", {})
    if not isinstance(random, dict):
        raise _plain_error("random", "must be a table of scene keys and distributions")
    for key, dist in random.items():
        spec.random[key] = _distribution(f"random.{key}", dist)
    if set(spec.grid) & set(spec.random):
        raise _plain_error(f"random.{sorted(set(spec.grid) & set(spec.random))[0]}", "is varied in [grid] too")
    if "samples" in data and not spec.random:
        raise _plain_error("samples", "draws from [random], which the spec does not have")
    if not spec.keys:
        raise _plain_error(str(path), "varies nothing: give [grid] or [random]")
    plot = data.get("plot", {})
    if not isinstance(plot, dict) or set(plot) - {"metric", "parameter"}:
        raise _plain_error("plot", "must be a table with metric and parameter")
    spec.plot_metric = plot.get("metric", spec.plot_metric)
    if spec.plot_metric not in PLOT_METRICS:
        raise _plain_error("plot.metric", f"must be one of {', '.join(PLOT_METRICS)}, got {spec.plot_metric!r}")
    spec.plot_parameter = plot.get("parameter", spec.keys[0])
    if spec.plot_parameter not in spec.keys:
        raise _plain_error("plot.parameter", f"must be a varied key ({', '.join(spec.keys)})")
    return spec


def _default(value: int | None, default: int) -> int:
    return default if value is None else value


def _distribution(key: str, dist: Any) -> tuple[str, list[Any]]:
    if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in _DISTRIBUTIONS:
        raise _plain_error(key, f"must be one of {{ {' | '.join(f'{d} = [...]' for d in _DISTRIBUTIONS)} }}")
    kind, args = next(iter(dist.items()))
    if not isinstance(args, list) or not args:
        raise _plain_error(f"{key}.{kind}", f"must be a non-empty list, got {args!r}")
    if kind == "choice":
        return kind, args
    numbers = all(isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a) for a in args)
    if len(args) != 2 or not numbers or args[0] > args[1]:
        raise _plain_error(f"{key}.{kind}", f"must be [low, high] with low ≤ high, got {args!r}")
    if kind == "integers" and not all(isinstance(a, int) for a in args):
        raise _plain_error(f"{key}.{kind}", f"must be two integers, got {args!r}")
    if kind == "log_uniform" and not (args[0] * args[1] > 0):
        raise _plain_error(f"{key}.{kind}", f"must not be zero and have one sign at both ends, got {args!r}")
    return kind, args


def run_name(index: int) -> str:
    return f"run_{index:05d}"


@dataclass
class SweepResult:
    out: Path
    rows: list[dict[str, Any]]
    ran: int
    skipped: int

    def counts(self) -> dict[str, int]:
        statuses = [r["status"] for r in self.rows]
        return {s: statuses.count(s) for s in ("ok", "failed", "error")}


def run_sweep(
    spec: SweepSpec | str | Path,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    client: Any = None,
) -> SweepResult:
    """Runs every run of ``spec`` not yet finished in ``out`` on Dask, then writes ``sweep.csv``,
    ``sweep.parquet`` and ``sweep.png``.

    With no ``scheduler`` address (nor ``client``), a local cluster of ``workers`` processes (default: one
    per core, each run on its share of the cores) is started and stopped; with ``scheduler``
    (``tcp://host:port``), that cluster's workers run them (each on every core of its machine, unless
    ``AUGMPM_THREADS`` says otherwise). Every scene is checked before any run starts: bad input raises
    :class:`augmpm.SceneError` and runs nothing.
    """
    if not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    if workers is not None and workers < 1:
        raise _plain_error("--workers", f"must be at least 1, got {workers}")
    runs = spec.runs()
    for values in runs:
        load_scene(spec.scene, spec.overrides, values)  # bad input now, not on a worker
    out = output_dir(out)
    _check_same_sweep(out, spec, runs)
    (out / "runs").mkdir(exist_ok=True)
    names = [run_name(i) for i in range(len(runs))]
    todo = [i for i, name in enumerate(names) if not (out / "runs" / name / SUMMARY).exists()]
    summaries: dict[int, dict[str, Any]] = {}
    if todo:
        summaries = _run_on_dask(spec, out, runs, todo, scheduler, workers, progress, client)
    rows = []
    for i, values in enumerate(runs):
        summary = summaries.get(i) or _read_summary(out / "runs" / names[i])
        rows.append({"run": names[i], **values, **{c: summary.get(c) for c in SUMMARY_COLUMNS}})
    _write_table(out, spec, rows)
    _plot(out / "sweep.png", spec, rows)
    return SweepResult(out=out, rows=rows, ran=len(todo), skipped=len(runs) - len(todo))


def _check_same_sweep(out: Path, spec: SweepSpec, runs: list[dict[str, Any]]) -> None:
    """Writes ``sweep.json`` (the base scene, its overrides and every run's values), or checks that the sweep
    already in ``out`` is this one: a run directory must never mix two sweeps."""
    record = {
        "scene": load_scene(spec.scene, spec.overrides).to_json(),
        "steps": spec.steps,
        "render": spec.render,
        "runs": runs,
    }
    text = json.dumps(record, indent=1)
    path = out / "sweep.json"
    if path.exists():
        try:
            before = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            before = None
        if before != json.loads(text):
            raise _plain_error(
                "--out", f"{out} holds another sweep (its sweep.json differs from this spec): give another --out"
            )
    write_text(path, text)


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int | None, client: Any = None) -> Iterator[tuple[Any, int | None]]:
    """A Dask client and the threads each task's simulation should take: ``client`` itself if given;
    else one on the scheduler at ``scheduler`` (each run on every core of its worker's machine unless
    ``AUGMPM_THREADS`` says otherwise); else on a local cluster of ``workers`` processes (default: one per
    core, each run on its share of the cores), started and stopped here."""
    if client is not None:
        yield client, None
        return
    from distributed import Client

    if workers is not None and workers < 1:
        raise _plain_error("--workers", f"must be at least 1, got {workers}")
    if scheduler is not None:
        try:
            own = Client(scheduler, timeout="30s")
        except (OSError, TimeoutError, ValueError) as e:
            raise _plain_error("--scheduler", f"cannot reach {scheduler}: {e}") from None
        with own:
            yield own, None
        return
    cores = available_cores()
    n = workers or cores
    with local_cluster(n) as cluster, Client(cluster) as own:
        yield own, max(1, cores // n)


def local_cluster(workers: int) -> Any:
    """A Dask cluster of ``workers`` processes on this machine, one thread each, without a dashboard. Its
    scheduler still serves HTTP (metrics): on a free port of the loopback interface, not on 8787, where a
    second cluster (two sweeps at once, parallel tests) would warn that the port is taken, nor on every
    interface, where ``:0`` would put it."""
    from distributed import LocalCluster

    return LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        silence_logs=40,
    )


def _run_on_dask(
    spec: SweepSpec,
    out: Path,
    runs: list[dict[str, Any]],
    todo: list[int],
    scheduler: str | None,
    workers: int | None,
    progress: bool,
    client: Any,
) -> dict[int, dict[str, Any]]:
    from distributed import as_completed

    summaries: dict[int, dict[str, Any]] = {}
    with dask_client(scheduler, workers, client) as (client, threads):
        futures = {
            client.submit(
                run_one,
                load_scene(spec.scene, spec.overrides, runs[i]).to_json(),
                str(out / "runs" / run_name(i)),
                spec.steps,
                spec.render,
                spec.checkpoint_every,
                threads,
                key=f"augmpm-sweep-{run_name(i)}-{os.getpid()}-{wallclock.time_ns()}",
                pure=False,
            ): i
            for i in todo
        }
        bar = _bar(len(todo), progress)
        for future in as_completed(futures):
            i = futures[future]
            try:
                summaries[i] = future.result()
            except Exception as e:  # a worker lost too often, or an error outside the simulation
                summaries[i] = {"status": "error", "error": f"{type(e).__name__}: {e}", "dir": f"runs/{run_name(i)}"}
            bar.update(1)
        bar.close()
    return summaries


def run_one(
    scene: str,
    run_dir: str,
    steps: int | None,
    render: bool,
    checkpoint_every: int,
    threads: int | None,
) -> dict[str, Any]:
    """One run of a sweep (on a worker), of the scene ``scene`` (its JSON, meshes included: the worker reads
    no scene file): nothing when ``run_dir`` holds a finished run (its summary is returned), else continued
    from its checkpoint, else started; writes ``summary.json`` once finished. A scene the engine refuses is
    a finished, failed run; an error reading the run's own files is raised (the next call tries again)."""
    from augmpm.run import CHECKPOINT, resume_run, run_scene
    from augmpm.scene import scene_class

    path = Path(run_dir)
    if (path / SUMMARY).exists():
        return _read_summary(path)
    path.mkdir(parents=True, exist_ok=True)
    resumed = (path / CHECKPOINT).exists()
    with open(path / _ATTEMPTS, "a", encoding="utf-8") as log:
        log.write(f"{wallclock.strftime('%Y-%m-%dT%H:%M:%S')} {'resumed' if resumed else 'started'}\n")
    if resumed:
        result = resume_run(path, progress=False, threads=threads, raise_on_failure=False)
        summary = _summarize(path, result.error, result.wall_time)
        write_text(path / SUMMARY, json.dumps(summary, indent=1))
        return summary
    data = json.loads(scene)
    try:
        result = run_scene(
            scene_class(data).model_validate(data),
            path,
            steps=steps,
            progress=False,
            animation="mp4" if render else None,
            render=render,
            threads=threads,
            checkpoint_every=checkpoint_every,
            raise_on_failure=False,
        )
        summary = _summarize(path, result.error, result.wall_time)
    except _core.SceneError as e:
        # Refused by the engine (e.g. a body outside the walls at these values): a result of the sweep.
        summary = {**_summarize(path, f"bad input: {e}", 0.0), "frames": 0}
    write_text(path / SUMMARY, json.dumps(summary, indent=1))
    return summary


def _summarize(path: Path, error: str | None, run_time: float) -> dict[str, Any]:
    rows = []
    if (path / "metrics.csv").exists():
        with open(path / "metrics.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    attempts = (path / _ATTEMPTS).read_text(encoding="utf-8").splitlines() if (path / _ATTEMPTS).exists() else []
    return {
        "status": "failed" if error else "ok",
        "max_n_outside": max((int(r["n_outside"]) for r in rows), default=None),
        "max_penetration": max((float(r["max_penetration"]) for r in rows), default=None),
        "final_kinetic_energy": float(rows[-1]["kinetic_energy"]) if rows else None,
        "run_time": run_time,
        "attempts": len(attempts),
        "frames": len(rows),
        "error": error or "",
        "dir": f"runs/{path.name}",
    }


def _read_summary(path: Path) -> dict[str, Any]:
    try:
        return json.loads((path / SUMMARY).read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return {"status": "error", "error": f"no readable {SUMMARY}: {e}", "dir": f"runs/{path.name}"}


def _write_table(out: Path, spec: SweepSpec, rows: list[dict[str, Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = ["run", *spec.keys, *SUMMARY_COLUMNS]
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: "" if row.get(c) is None else row[c] for c in columns})
    write_text(out / "sweep.csv", text.getvalue())
    arrays = {c: _arrow_column([row.get(c) for row in rows]) for c in columns}
    buffer = pa.BufferOutputStream()
    pq.write_table(pa.table(arrays), buffer)
    write_bytes(out / "sweep.parquet", buffer.getvalue().to_pybytes())


def _arrow_column(values: list[Any]) -> Any:
    """A Parquet column: integers, floats (integers among floats as floats), booleans, or text."""
    import pyarrow as pa

    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, pa.bool_())
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.array(values, pa.int64())
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    return pa.array([None if v is None else v if isinstance(v, str) else json.dumps(v) for v in values], pa.string())


def _plot(path: Path, spec: SweepSpec, rows: list[dict[str, Any]]) -> None:
    """``[plot] metric`` against ``[plot] parameter``, one series per method when the method is varied."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key, metric = spec.plot_parameter, spec.plot_metric
    fig, ax = plt.subplots(figsize=(6, 4))
    by = "method" if "method" in spec.keys and key != "method" else None
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        if row.get("status") in ("ok", "failed") and row.get(metric) is not None:
            groups.setdefault(str(row[by]) if by else "", []).append(row)
    for label, members in groups.items():
        xs = [m[key] for m in members]
        numeric = all(isinstance(x, int | float) and not isinstance(x, bool) for x in xs)
        xs = xs if numeric else [json.dumps(x) if not isinstance(x, str) else x for x in xs]
        ys = [m[metric] for m in members]
        ax.plot(xs, ys, "o", label=label or None, alpha=0.8)
        failed = [(x, y) for x, y, m in zip(xs, ys, members, strict=True) if m["status"] == "failed"]
        if failed:
            first = label == next(iter(groups))
            ax.plot(*zip(*failed, strict=True), "x", color="k", label="failed run" if first else None)
    ax.set_xlabel(key)
    ax.set_ylabel(f"{metric} ({_UNITS[metric]})")
    ax.set_title(f"{metric} over {len(rows)} runs")
    if by or any(r.get("status") == "failed" for r in rows):
        ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def _bar(total: int, enabled: bool, label: str = "sweep", unit: str = "run") -> Any:
    from augmpm.run import _NoBar

    if not enabled:
        return _NoBar()
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc=label, unit=unit, file=sys.stderr, dynamic_ncols=True)


def format_summary(result: SweepResult) -> str:
    counts = result.counts()
    lines = [
        f"{len(result.rows)} runs in {result.out}: {counts['ok']} ok, {counts['failed']} failed, "
        f"{counts['error']} not completed ({result.ran} run now, {result.skipped} already finished)",
    ]
    done = [r for r in result.rows if r["status"] in ("ok", "failed")]
    if done:
        deepest = max(done, key=lambda r: r.get("max_penetration") or 0.0)
        lines.append(
            f"deepest past a wall: {deepest.get('max_penetration') or 0.0:.3g} h in {deepest['run']}; "
            f"most particles outside: {max(r.get('max_n_outside') or 0 for r in done)}"
        )
    lines.extend(f"  {r['run']}: {r['status']}: {r['error']}" for r in result.rows if r["status"] != "ok")
    lines.append("written: sweep.csv, sweep.parquet, sweep.png, runs/")
    return "\n".join(lines)


__all__ = ["PLOT_METRICS", "SUMMARY_COLUMNS", "SweepResult", "SweepSpec", "load_spec", "run_one", "run_sweep"]
