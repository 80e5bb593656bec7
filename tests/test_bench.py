"""``augmpm bench``: its scenes, its measurements and its report."""

from __future__ import annotations

import json
import statistics

import numpy as np
import pytest

import augmpm
from augmpm import bench
from augmpm.scene import load_scene

from .conftest import ROOT


@pytest.mark.parametrize("resolution", [128, 256, 512])
def test_rust_bench_scenes_match_the_generator(resolution):
    """benches/scenes/*.json (read by the criterion benches) are what augmpm.bench generates."""
    committed = json.loads((ROOT / "benches" / "scenes" / f"dam_break_{resolution}.json").read_text())
    assert committed == json.loads(bench.dam_break_scene(resolution).to_json())


def test_rust_fig1_scene_matches_the_paper_scene():
    committed = json.loads((ROOT / "benches" / "scenes" / "fig1_fluid_incline_noslip.json").read_text())
    assert committed == json.loads(load_scene(ROOT / "scenes" / "paper" / "fluid_incline_noslip.toml").to_json())


def test_dam_break_sizes_and_walls():
    """The smallest dam break has ~8k particles, and its water column lies along inclined walls:
    about a tenth of its particles start within two cells of a wall (their MLS systems see it)."""
    from augmpm.simulation import Simulation

    sim = Simulation(bench.dam_break_scene(128), "augmented")
    assert 7_000 < sim.num_particles < 9_000
    near = sim.wall_distance(sim.positions) > -2 * sim.cell_size
    assert near.mean() > 0.05


def test_fig1_bench_and_report(monkeypatch):
    """A short Fig. 1 measurement scales to 10,000 steps and formats into the README's tables."""
    rows = bench.bench_fig1(ROOT / "scenes" / "paper" / "fluid_incline_noslip.toml", steps=40, threads=1)
    assert [r["method"] for r in rows] == ["naive", "augmented"]
    for r in rows:
        assert r["particles"] > 1_000 and r["particle_steps_per_s"] > 0
        assert r["seconds_10k_steps"] == pytest.approx(r["seconds"] * 10_000 / 40)
        authors = bench.AUTHORS_FIG1_SECONDS[r["method"]]
        assert r["speedup_vs_authors"] == pytest.approx(authors / r["seconds_10k_steps"])
    report = {"machine": bench._machine(1), "quick": True, "rows": rows}
    text = bench.format_report(report)
    assert "| naive | 1 | 40 |" in text and "| augmented | 1 | 40 |" in text


def test_output_bench_alternates_runs_and_reports_the_median_share(monkeypatch):
    """The output cost alternates a run with every output and one without, each first in every other round,
    after an untimed warm-up; its share is the median of the rounds' shares, within their range, and the
    report gives it against the 10% target."""
    import augmpm.run

    calls = []
    run_scene = augmpm.run.run_scene

    def recorded_run(scene, out, **kwargs):
        calls.append(("full", kwargs["method"]) if "method" in kwargs else ("warm-up", None))
        return run_scene(scene, out, **kwargs)

    class Recorded(bench.Simulation):
        def step(self, n=1):
            calls.append(("bare", self.method))
            return super().step(n)

    monkeypatch.setattr(augmpm.run, "run_scene", recorded_run)
    monkeypatch.setattr(bench, "Simulation", Recorded)
    rows = bench.bench_output(ROOT / "scenes" / "paper" / "fluid_incline_noslip.toml", steps=200, threads=1, rounds=2)
    order = ["bare", "full", "full", "bare"]
    assert calls == [("warm-up", None), *((k, m) for m in bench.METHODS for k in order)]
    with pytest.raises(ValueError, match="even"):
        bench.bench_output(ROOT / "scenes" / "paper" / "fluid_incline_noslip.toml", steps=200, threads=1, rounds=3)
    assert [r["method"] for r in rows] == ["naive", "augmented"]
    for r in rows:
        assert r["rounds"] == 2 and r["frames"] == 3
        low, high = r["output_fraction_range"]
        assert 0.0 <= low <= r["output_fraction"] <= high < 1.0
        assert r["run_with_output_s"] > 0 and r["simulation_s"] > 0
    text = bench.format_report({"machine": bench._machine(1), "quick": True, "rows": rows})
    assert "| naive | 200 | 3 |" in text and "| ≤ 10% |" in text


def test_moving_walls_bench_and_report():
    """The moving-walls case times each shipped moving scene against itself with still walls, both methods,
    the same steps each, and reports the ratio of their step times."""
    rows = bench.bench_moving(steps=8, threads=1)
    assert [(r["case"], r["method"]) for r in rows] == [
        (f"moving_{name.split('/')[-1]}", m) for name in bench.MOVING_SCENES for m in bench.METHODS
    ]
    for r in rows:
        assert r["steps"] == 8 and r["moving_over_still"] > 0
        assert r["moving_over_still"] == pytest.approx(r["seconds"] / r["still_seconds"])
    text = bench.format_report({"machine": bench._machine(1), "quick": True, "rows": rows})
    assert "| shaken_tank | augmented |" in text


def test_rigid_coupling_bench_holds_the_bodies_where_they_are(monkeypatch):
    """The coupling case times the rigid scene with its bodies free against the same state with each body
    a wall held where the body is: the held walls' outlines are the bodies' (to 1e-12 m), and the report
    gives both ratios of step times."""
    monkeypatch.setattr(bench, "RIGID_START", 0.05)
    scene = bench.load_scene(bench.RIGID_SCENE)
    free = augmpm.Simulation(scene, "naive")
    free.step(40)
    held = augmpm.Simulation(bench._held_walls(scene, free, motion=True), "naive")
    for body in range(len(scene.walls), len(scene.walls) + len(scene.rigid_bodies)):
        a, b = free.wall_outlines()[body][0], held.wall_outlines()[body][0]
        assert a.shape == b.shape and np.abs(a - b).max() < 1e-12
    rows = bench.bench_rigid(steps=8, threads=1)
    assert [(r["case"], r["method"]) for r in rows] == [("rigid_coupling", m) for m in bench.METHODS]
    assert all(r["steps"] == 8 and r["free_over_held"] > 0 and r["free_over_still"] > 0 for r in rows)
    text = bench.format_report({"machine": bench._machine(1), "quick": True, "rows": rows})
    assert "| augmented | 3,767 | 8 |" in text


def test_thread_scaling_alternates_one_thread_many_and_the_machines_ceiling():
    """The thread-scaling case steps the dam break on one thread, on N, and as N one-thread runs at once,
    the same steps each, in alternating order; its speed-up and the machine's ceiling are the medians of the
    rounds' ratios, and the report gives them against the 1.85x target."""
    row = bench.bench_scaling(128, steps=2, threads=2, warm_up=1, rounds=2)
    assert row["case"] == "scaling_128" and row["threads"] == 2 and row["particles"] > 4_096
    assert len(row["speedup_rounds"]) == len(row["ceiling_rounds"]) == 2
    assert row["speedup"] == pytest.approx(statistics.median(row["speedup_rounds"]))
    assert row["ceiling"] == pytest.approx(statistics.median(row["ceiling_rounds"]))
    assert all(r > 0 for r in row["speedup_rounds"] + row["ceiling_rounds"])
    assert {"p2g", "g2p"} <= set(row["stage_speedups"])
    text = bench.format_report({"machine": bench._machine(2), "quick": True, "rows": [row]})
    assert "| 128², after 1 steps | " in text and "≥ 1.85× |" in text
    with pytest.raises(ValueError, match="rounds"):
        bench.bench_scaling(128, steps=1, threads=2, warm_up=0, rounds=3)


def test_memory_is_measured_in_a_fresh_process():
    """Peak memory per particle of the 128² dam break: at least the 104 B of a fluid particle's state (the
    state fields but F, which only solids keep; plus the grid, ~17k nodes), and not absurd."""
    size = {f["name"]: int(np.dtype(f["dtype"]).itemsize * np.prod(f["shape"])) for f in augmpm._core.state_fields()}
    state = sum(size.values()) - size["f"]
    assert state == 104
    m = bench._memory_in_subprocess(128, "naive", "f64")
    assert state <= m["peak_bytes_per_particle"] < 2_000
    assert state <= m["per_particle_without_grid"] <= 120


def test_3d_dam_break_sizes_bench_and_report(monkeypatch):
    """The 3D dam break: ~20k particles on 32³ (~160k on 64³, ~1M on 128³ by the same rule), its water
    against the turned tank's walls (a fifth of its particles within two cells of one); one short
    interleaved measurement of every precision and method gives rates, the augmented/naive ratio, memory
    in a fresh process, and rows of the report's table."""
    from augmpm.simulation import Simulation

    sim = Simulation(bench.dam_break_3d_scene(32), "augmented")
    assert 15_000 < sim.num_particles < 25_000 and sim.dim == 3
    assert (sim.wall_distance(sim.positions) > -2 * sim.cell_size).mean() > 0.2
    # The 3D target's row, moved to this size and thread count: only it carries the target.
    monkeypatch.setattr(bench, "TARGET_3D_RESOLUTION", 32)
    monkeypatch.setattr(bench, "TARGET_3D_THREADS", 1)
    rows = bench.bench_dam_break(32, steps=4, threads=(1,), dim=3)
    assert [(r["precision"], r["method"]) for r in rows] == [(p, m) for p in bench.PRECISIONS for m in bench.METHODS]
    for r in rows:
        assert r["case"] == "dam_break_3d_32" and r["steps"] == 4 and r["particle_steps_per_s"] > 0
        assert r["augmented_over_naive"] > 0 and r["memory"]["peak_bytes_per_particle"] > 100
    text = bench.format_report({"machine": bench._machine(1), "quick": True, "rows": rows})
    assert "| 32³ | " in text and "dam_break_3d_32 f32 augmented 1t" in text
    tagged = [(r["precision"], r["method"]) for r in rows if "target_particle_steps_per_s" in r]
    assert tagged == [("f32", "naive")] and "3D target: the 32³ dam break" in text


def test_3d_target_is_reported_for_the_1m_particle_f32_row():
    """Issue 16's 3D target (≥ 8 M particle-steps/s, the 128³ fluid, naive f32, 2 threads) is read from that row
    alone, and the report says whether it is met and by how much it is missed."""
    row = {
        "case": "dam_break_3d_128",
        "dim": 3,
        "particles": 976_241,
        "precision": "f32",
        "method": "naive",
        "threads": 2,
        "particle_steps_per_s": 6.4e6,
        "augmented_over_naive": 1.0,
        "target_particle_steps_per_s": bench.TARGET_3D_RATE,
        "memory": {"peak_bytes_per_particle": 195.0, "per_particle_without_grid": 88.0},
        "stages_s": dict.fromkeys(bench.STAGES, 1.0),
    }
    text = bench.format_report({"machine": bench._machine(2), "quick": False, "rows": [row]})
    assert "3D target: the 128³ dam break (976,241 particles), f32 naive on 2 threads, 6.4 M" in text
    assert "against ≥ 8 M: missed by 1.25×." in text
    text = bench.format_report(
        {"machine": bench._machine(2), "quick": False, "rows": [row | {"particle_steps_per_s": 8.1e6}]}
    )
    assert "8.1 M particle-steps/s against ≥ 8 M: met." in text


def _fake_peers(tmp_path, body: str):
    peers = tmp_path / "peers"
    peers.mkdir()
    (peers / "run.sh").write_text(body)
    return peers


def test_peers_bench_alternates_with_the_peers_and_reports_the_ratio(tmp_path):
    """The peers' script runs once a round, at the dam break's size, and each augmpm configuration's
    median rate is reported over the faster peer's median (a stand-in script with known rates)."""
    peers = _fake_peers(
        tmp_path,
        'echo "$1 $2 $3" >> "$(dirname "$0")/calls"\n'
        'echo "building ..."\n'
        'echo \'RESULT {"impl": "taichi_pt", "n": 8192, "pss_median": 1e6}\'\n'
        'echo \'RESULT {"impl": "rust_rayon", "n": 8192, "pss_median": 4e6}\'\n',
    )
    rows = bench.bench_peers(peers, 128, steps=4, threads=1, rounds=2, log=lambda s: None)
    assert (peers / "calls").read_text().splitlines() == ["S 1 4", "S 1 4"]
    assert [(r["precision"], r["method"]) for r in rows] == [("f32", "naive"), ("f64", "naive"), ("f64", "augmented")]
    for r in rows:
        assert r["faster_peer"] == "rust_rayon" and r["peers"] == {"taichi_pt": 1e6, "rust_rayon": 4e6}
        assert len(r["rounds_particle_steps_per_s"]) == 2
        assert r["over_faster_peer"] == pytest.approx(r["particle_steps_per_s"] / 4e6)
    augmented = rows[2]
    assert augmented["augmented_over_naive"] == pytest.approx(
        rows[1]["particle_steps_per_s"] / augmented["particle_steps_per_s"]
    )
    text = bench.format_report({"machine": bench._machine(1), "quick": True, "rows": rows})
    assert "over the faster peer" in text and "rust_rayon 4.0" in text


def test_peers_that_fail_or_are_missing_are_named(tmp_path):
    """A missing script, a script that fails and one that prints no result are errors that say which."""
    with pytest.raises(bench.PeerError, match=r"run\.sh not found"):
        bench.bench_peers(tmp_path, 128, steps=2, threads=1, rounds=1)
    failing = _fake_peers(tmp_path, 'echo "cargo: no network" >&2; exit 3\n')
    with pytest.raises(bench.PeerError, match="exited with 3: cargo: no network"):
        bench.bench_peers(failing, 128, steps=2, threads=1, rounds=1, log=lambda s: None)
    (failing / "run.sh").write_text("echo nothing\n")
    with pytest.raises(bench.PeerError, match="no RESULT line"):
        bench.bench_peers(failing, 128, steps=2, threads=1, rounds=1, log=lambda s: None)


def test_stage_bytes_follow_the_state_field_table():
    """The roofline's bytes per particle-step are the sizes of the engine's per-particle arrays each stage
    reads and writes (2D f64 fluid: no F), so a field that changes size changes them."""
    size = {f["name"]: int(np.dtype(f["dtype"]).itemsize * np.prod(f["shape"])) for f in augmpm._core.state_fields()}
    reads_p2g = ["x", "v", "c", "jp", "mass", "vol0", "body"]
    reads_g2p = ["x", "v", "c", "jp", "body", "mass"]
    writes_g2p = ["x", "v", "c", "jp"]
    moved = bench.stage_bytes("f64", 2)
    assert moved["density"] == 0, "the default fluid's J-bar sums ride on P2G and G2P"
    assert moved["p2g"] == sum(size[k] for k in reads_p2g) + size["density"]
    assert moved["g2p"] == sum(size[k] for k in reads_g2p + writes_g2p)
    assert bench.stage_bytes("f64", 2, keeps_f=True)["p2g"] == moved["p2g"] + size["f"]


def test_roofline_table_reads_the_machine_roofs():
    """The machine's roofs are measured (positive, finite) and the report's roofline gives each stage's
    share of the bandwidth from its measured time."""
    roofs = bench.machine_roofs(1, mebibytes=4)
    assert 0 < roofs["bandwidth_GBps"] < 1e4 and 0 < roofs["peak_GFLOPs"] < 1e5
    row = {
        "case": "dam_break_128",
        "dim": 2,
        "precision": "f64",
        "method": "naive",
        "threads": 1,
        "particles": 1000,
        "steps": 10,
        "stages_s": {"density": 1e-3, "p2g": 2e-3, "g2p": 0.0},
    }
    lines = bench._roofline({"roofs": {"bandwidth_GBps": 10.0, "peak_GFLOPs": 50.0, "threads": 1}}, [row])
    # p2g: 100 B x 1,000 particles x 10 steps in 2 ms = 0.5 GB/s, 5% of 10 GB/s; the density stage moves no
    # particle bytes (the bench fluid's J-bar sums ride on P2G and G2P), and g2p took no time: no figure.
    assert "| dam_break_128 f64 naive 1t | – | 100 B / 0.5 (5%) | – |" in lines


def test_compare_builds_alternates_two_builds_in_one_process():
    """benches/compare_builds.py steps a dam break with each build and prints, per stage, the two medians and
    the ratios: the same build against itself gives step times and positive ratios; an odd --rounds is refused;
    --scene steps a shipped scene instead, and a scene it cannot read is refused by name; --precision f32 steps
    the dam break in single precision."""
    import subprocess
    import sys

    script = ROOT / "benches" / "compare_builds.py"
    engine = augmpm._core.__file__
    args = [sys.executable, str(script), engine, engine, "--resolution", "128", "--steps", "5"]
    run = subprocess.run([*args, "--rounds", "4"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    rows = {line.split()[0]: line.split()[1:] for line in run.stdout.splitlines()[2:]}
    assert {"step", "p2g", "g2p"} <= rows.keys()
    a, b, median, fastest = (float(rows["step"][i].strip("[],")) for i in (0, 1, 2, 5))
    assert a > 0 and b > 0
    # Four rounds are too few for the median's 95% interval.
    assert rows["step"][6] == "–"
    # One engine twice: only the machine's noise separates the rounds, and that is not asserted (a loaded
    # 2-core host put one A/A median at 3.8×); the ratios are the medians' and positive.
    assert median > 0 and fastest > 0 and np.isfinite([median, fastest]).all()
    refused = subprocess.run([*args, "--rounds", "3"], capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "--rounds 3" in refused.stderr
    on_scene = [sys.executable, str(script), engine, engine, "--steps", "5", "--rounds", "2", "--scene"]
    fig1 = subprocess.run([*on_scene, "paper/fluid_incline_noslip"], capture_output=True, text=True, timeout=120)
    assert fig1.returncode == 0, fig1.stderr
    assert fig1.stdout.startswith("paper/fluid_incline_noslip, naive")
    rows = {line.split()[0]: line.split()[1:] for line in fig1.stdout.splitlines()[2:]}
    assert {"step", "p2g", "g2p"} <= rows.keys()
    a, b, median = (float(rows["step"][i].strip("[],")) for i in (0, 1, 2))
    assert a > 0 and b > 0 and median > 0
    missing = subprocess.run([*on_scene, "no/such_scene"], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and "--scene: no/such_scene" in missing.stderr
    both = subprocess.run([*on_scene, "paper/fluid_incline_noslip", "--dim", "3"], capture_output=True, text=True)
    assert both.returncode == 2 and "--dim, --resolution and --precision" in both.stderr
    single = subprocess.run([*args, "--rounds", "2", "--precision", "f32"], capture_output=True, text=True, timeout=120)
    assert single.returncode == 0, single.stderr
    assert single.stdout.startswith("2D dam break at 128, f32, naive")


def test_median_interval_is_the_sign_tests():
    """The 95% interval compare_builds gives for a median ratio covers the median of any continuous
    distribution with probability at least 95% (binomial tails of n draws about it, halves of at most
    2.5% each), and is the narrowest pair of order statistics that does: at n = 30, the 10th and 21st
    smallest (coverage 95.7%), at n = 60 the 22nd and 39th; none below 6 draws."""
    import importlib.util
    from math import comb

    spec = importlib.util.spec_from_file_location("compare_builds", ROOT / "benches" / "compare_builds.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    draws = [float(v) for v in range(1, 81)]
    assert module.median_interval(draws[:30]) == (10.0, 21.0)
    assert module.median_interval(draws[:60]) == (22.0, 39.0)
    assert module.median_interval(draws[:5]) is None and module.median_interval(draws[:6]) == (1.0, 6.0)
    # Many rounds: 2ⁿ past a float's range is no error (n = 2,000: ranks 956 and 1,045, ±1.96 √n / 2 about n/2).
    assert module.median_interval([float(v) for v in range(1, 2001)]) == (956.0, 1045.0)
    # The order does not matter, and the coverage is at least the confidence, one rank inward it is not.
    rng = np.random.default_rng(3)
    for n in (6, 7, 12, 30, 31, 60, 80):
        values = list(rng.permutation(draws[:n]))
        low, high = module.median_interval(values)
        k = int(low)
        assert high == n + 1 - k
        outside = sum(comb(n, j) for j in range(k)) / 2**n
        assert 1 - 2 * outside >= 0.95
        inward = sum(comb(n, j) for j in range(k + 1)) / 2**n
        assert 1 - 2 * inward < 0.95
