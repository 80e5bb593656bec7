"""Sweeps on Dask (`augmpm sweep`): the spec, the runs' order and values, the table and plot, resuming, a
worker killed mid-run, and that every run is bitwise the run `augmpm run` makes of the same scene."""

from __future__ import annotations

import csv
import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import augmpm
from augmpm.cli import main
from augmpm.run import run_scene
from augmpm.scene import load_scene
from augmpm.sweep import SUMMARY_COLUMNS, load_spec, run_sweep

#: A small dam break (24 cells across, ~400 particles): a run takes a fraction of a second.
SMALL = """
scene = "dam_break"
steps = 120
set = ["grid.resolution=24", "time.output_interval=20"]
samples = 2
seed = 3

[grid]
method = ["naive", "augmented"]

[random]
"bodies[0].material.viscosity" = { uniform = [0.1, 1.0] }
"""


def _spec(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _same_outputs(a: Path, b: Path) -> None:
    """The run directories hold the same metrics and particle frames, byte for byte."""
    assert (a / "metrics.csv").read_bytes() == (b / "metrics.csv").read_bytes()
    frames = sorted(p.name for p in (a / "particles").glob("frame_*.npz"))
    assert frames == sorted(p.name for p in (b / "particles").glob("frame_*.npz")) and frames
    for f in frames:
        assert (a / "particles" / f).read_bytes() == (b / "particles" / f).read_bytes(), f


def test_runs_are_the_grid_times_the_samples_and_deterministic(tmp_path):
    """The runs are every grid point (its last key fastest) times `samples` draws, drawn from the seed:
    the same spec gives the same values, another seed others, within the distribution's bounds."""
    spec = load_spec(_spec(tmp_path, SMALL))
    runs = spec.runs()
    assert [r["method"] for r in runs] == ["naive", "naive", "augmented", "augmented"]
    viscosities = [r["bodies[0].material.viscosity"] for r in runs]
    assert all(0.1 <= v <= 1.0 for v in viscosities) and len(set(viscosities)) == 4
    assert load_spec(_spec(tmp_path, SMALL, "again.toml")).runs() == runs
    other = load_spec(_spec(tmp_path, SMALL.replace("seed = 3", "seed = 4"), "other.toml")).runs()
    assert [r["bodies[0].material.viscosity"] for r in other] != viscosities
    text = """scene = "dam_break"
samples = 500
[random]
a = { log_uniform = [-20.0, -2.0] }
b = { integers = [1, 3] }
c = { choice = ["slip", "sticky"] }
"""
    drawn = load_spec(_spec(tmp_path, text, "dists.toml")).runs()
    a = np.array([r["a"] for r in drawn])
    assert np.all((a >= -20.0) & (a <= -2.0))
    # Log-uniform: half the draws below the geometric mean of the ends (sqrt(40) ≈ 6.3), within 3 sigma.
    assert abs(np.mean(-a < np.sqrt(40.0)) - 0.5) < 3 * 0.5 / np.sqrt(500)
    assert {r["b"] for r in drawn} == {1, 2, 3}
    assert {r["c"] for r in drawn} == {"slip", "sticky"}


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ('steps = 5\n[grid]\nmethod = ["naive"]', "scene"),
        ('scene = "dam_break"\nstep = 5\n[grid]\nmethod = ["naive"]', "step"),
        ('scene = "dam_break"\n[grid]\nmethod = []', "grid.method"),
        ('scene = "dam_break"\n[random]\n"time.cfl" = { normal = [0, 1] }', "random.time.cfl"),
        ('scene = "dam_break"\n[random]\n"time.cfl" = { uniform = [0.3, 0.1] }', "random.time.cfl.uniform"),
        ('scene = "dam_break"\n[random]\n"gravity[1]" = { log_uniform = [-1.0, 1.0] }', "random.gravity[1]"),
        ('scene = "dam_break"\nsamples = 3\n[grid]\nmethod = ["naive"]', "samples"),
        ('scene = "dam_break"', "varies nothing"),
        ('scene = "dam_break"\n[grid]\nmethod = ["naive"]\n[plot]\nmetric = "speed"', "plot.metric"),
        ('scene = "dam_break"\n[grid]\nmethod = ["naive"]\n[plot]\nparameter = "seed"', "plot.parameter"),
    ],
)
def test_a_bad_spec_names_its_key(tmp_path, text, key):
    """A bad spec is refused naming the key and the reason, before anything runs."""
    with pytest.raises(augmpm.SceneError, match=key.replace("[", r"\[").replace("]", r"\]")):
        load_spec(_spec(tmp_path, text))


def test_a_bad_scene_value_is_refused_before_any_run(tmp_path, capsys):
    """A varied value the scene refuses stops the sweep before it starts (exit 2), naming the key; nothing
    is written for any run."""
    path = _spec(tmp_path, 'scene = "dam_break"\n[grid]\n"time.cfl" = [0.25, -1.0]\n')
    assert main(["sweep", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "time.cfl" in err and "bad input" in err
    assert not (tmp_path / "out" / "runs").exists()


def test_sweep_table_plot_resume_and_bitwise_runs(tmp_path, client):
    """A sweep writes each run as `augmpm run` would (bitwise the same metrics and particle frames), a
    table of every run's values and summary in CSV and Parquet, and a plot; run again it redoes nothing."""
    spec = _spec(tmp_path, SMALL)
    out = tmp_path / "out"
    result = run_sweep(spec, out, progress=False, client=client)
    assert result.counts() == {"ok": 4, "failed": 0, "error": 0} and result.ran == 4
    with open(out / "sweep.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["run", "method", "bodies[0].material.viscosity", *SUMMARY_COLUMNS]
    table = pq.read_table(out / "sweep.parquet").to_pylist()
    assert [r["run"] for r in table] == [r["run"] for r in rows] == [f"run_{i:05d}" for i in range(4)]
    for row, parquet, values in zip(rows, table, load_spec(spec).runs(), strict=True):
        assert float(row["bodies[0].material.viscosity"]) == parquet["bodies[0].material.viscosity"]
        assert parquet["bodies[0].material.viscosity"] == values["bodies[0].material.viscosity"]
        assert parquet["status"] == "ok" and parquet["attempts"] == 1 and parquet["frames"] == 7
        metrics = list(csv.DictReader(open(out / parquet["dir"] / "metrics.csv", newline="", encoding="utf-8")))
        assert parquet["final_kinetic_energy"] == float(metrics[-1]["kinetic_energy"])
        assert parquet["max_penetration"] == max(float(m["max_penetration"]) for m in metrics)
    assert (out / "sweep.png").stat().st_size > 0
    # The last run, alone, as `augmpm run dam_break --steps 120 --set ...` makes it.
    last = load_spec(spec).runs()[3]
    alone = tmp_path / "alone"
    scene = load_scene("dam_break", ["grid.resolution=24", "time.output_interval=20"], last)
    run_scene(scene, alone, steps=120, progress=False, animation=None, render=False)
    _same_outputs(out / "runs" / "run_00003", alone)
    # Again: nothing is run, the table is the same.
    stamp = (out / "runs" / "run_00000" / "summary.json").stat().st_mtime_ns
    again = run_sweep(spec, out, progress=False, client=client)
    assert again.ran == 0 and again.skipped == 4
    assert (out / "runs" / "run_00000" / "summary.json").stat().st_mtime_ns == stamp
    assert pq.read_table(out / "sweep.parquet").to_pylist() == table
    # Another spec may not write into this sweep's directory.
    other = _spec(tmp_path, SMALL.replace("seed = 3", "seed = 9"), "other.toml")
    with pytest.raises(augmpm.SceneError, match="another sweep"):
        run_sweep(other, out, progress=False, client=client)


def test_a_killed_worker_loses_only_its_run_which_resumes(tmp_path, client):
    """A worker killed (SIGKILL) mid-run: its run restarts on a worker from its last checkpoint, the other
    run is untouched, and both end bitwise as the same scenes run alone without interruption."""
    text = """scene = "dam_break"
steps = 1200
set = ["time.output_interval=40"]
[grid]
"bodies[0].material.viscosity" = [0.5, 1.0]
"""
    spec = _spec(tmp_path, text)
    out = tmp_path / "out"
    done: dict = {}
    thread = threading.Thread(target=lambda: done.update(result=run_sweep(spec, out, progress=False, client=client)))
    thread.start()
    killed = None
    deadline = time.monotonic() + 120
    while killed is None and time.monotonic() < deadline and thread.is_alive():
        time.sleep(0.05)
        for run in (out / "runs").glob("run_*"):
            metrics = run / "metrics.csv"
            if (run / "summary.json").exists() or not (run / "checkpoint.npz").exists() or not metrics.exists():
                continue
            if len(metrics.read_text(encoding="utf-8").splitlines()) < 4:
                continue
            pids = client.run(os.getpid)
            for worker, keys in client.processing().items():
                if any(run.name in str(k) for k in keys):
                    os.kill(pids[worker], signal.SIGKILL)
                    killed = run.name
            break
    thread.join(timeout=300)
    assert killed is not None, "no run was caught mid-way"
    result = done["result"]
    assert result.counts() == {"ok": 2, "failed": 0, "error": 0}
    attempts = {r["run"]: r["attempts"] for r in result.rows}
    assert attempts[killed] == 2 and sum(attempts.values()) == 3
    log = (out / "runs" / killed / "attempts.log").read_text(encoding="utf-8").split()
    assert log[1::2] == ["started", "resumed"]
    for i, values in enumerate(load_spec(spec).runs()):
        alone = tmp_path / f"alone_{i}"
        run_scene(
            load_scene("dam_break", ["time.output_interval=40"], values),
            alone,
            steps=1200,
            progress=False,
            animation=None,
            render=False,
        )
        _same_outputs(out / "runs" / f"run_{i:05d}", alone)
    summary = json.loads((out / "runs" / killed / "summary.json").read_text(encoding="utf-8"))
    assert summary["frames"] == 31


def test_the_shipped_example_spec_is_valid():
    """The README's example sweep reads, and each of its 12 runs is a valid scene."""
    spec = load_spec(Path(__file__).resolve().parents[1] / "sweeps" / "dam_break_viscosity.toml")
    runs = spec.runs()
    assert len(runs) == 12
    for values in runs:
        load_scene(spec.scene, spec.overrides, values)


def test_workers_with_a_scheduler_is_refused(tmp_path, capsys):
    """`--workers` sizes the local cluster only: with `--scheduler` it is bad input, before anything runs."""
    path = _spec(tmp_path, SMALL)
    argv = ["sweep", str(path), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"]
    assert main(argv) == 2
    assert "--workers" in capsys.readouterr().err


def test_a_local_cluster_does_not_warn_when_the_dashboard_port_is_taken():
    """Two local clusters at once (two sweeps, parallel tests) start without a warning: the scheduler's HTTP
    server takes a free port, not 8787, which another may hold, and only on the loopback interface."""
    import socket
    import warnings

    import distributed

    from augmpm.sweep import local_cluster

    with socket.socket() as held, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            held.bind(("", 8787))
            held.listen()
        except OSError:
            pass  # already taken by something else: the case under test
        with local_cluster(1) as cluster, distributed.Client(cluster) as c:
            assert c.submit(sum, [1, 2]).result() == 3
            server = cluster.scheduler.services["dashboard"]
            assert server.port != 8787 and server.address == "127.0.0.1"
    assert not [w for w in caught if "already in use" in str(w.message)]
