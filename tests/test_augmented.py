"""The paper's method end to end: the Fig. 1 scene, `augmpm compare` and `augmpm interp-test`."""

from __future__ import annotations

import csv
import json

import numpy as np

import augmpm
from augmpm.cli import main

from .conftest import SCENES


def test_fig1_augmented_keeps_particles_inside_while_naive_leaks():
    """Fig. 1 (viscous fluid, no-slip incline), 2,000 steps: the naive grid lets particles sink
    through the inclined wall (about 300 of 1,526 by then); the augmented grid keeps every particle
    inside at every 100th step."""
    scene = augmpm.load_scene(SCENES / "paper" / "fluid_incline_noslip.toml")
    naive, aug = augmpm.Simulation(scene, "naive"), augmpm.Simulation(scene, "augmented")
    assert np.array_equal(naive.positions, aug.positions)  # same initial particles
    worst_aug = 0
    for _ in range(20):
        naive.step(100)
        aug.step(100)
        worst_aug = max(worst_aug, aug.metrics()["n_outside"])
    assert worst_aug == 0
    assert naive.metrics()["n_outside"] > 0.1 * naive.num_particles
    assert naive.metrics()["max_penetration"] > 0.3
    assert aug.metrics()["ill_conditioned"] == 0
    # The wall takes the fluid's weight in both: it settles, it does not fall through.
    assert np.mean(aug.positions[:, 1]) > 0.12


def test_augmented_builds_for_every_shipped_scene():
    for path in sorted(SCENES.rglob("*.toml")):
        sim = augmpm.Simulation(augmpm.load_scene(path), method="augmented")
        assert len(sim.boundary_points) > 0
        sim.step(2)
        assert sim.metrics()["n_outside"] == 0


def test_compare_writes_both_runs_and_the_comparison(tmp_path, capsys):
    out = tmp_path / "cmp"
    scene = SCENES / "paper" / "fluid_incline_noslip.toml"
    assert main(["compare", str(scene), "--out", str(out), "--steps", "200", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "naive" in printed and "augmented" in printed and "outside" in printed
    for m in ("naive", "augmented"):  # each a full run directory, its animation included
        assert (out / m / "metrics.csv").exists() and (out / m / "particles.pvd").exists()
        assert (out / m / "animation.mp4").stat().st_size > 1000
    with open(out / "comparison.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == [
        "step",
        "time",
        "naive_n_outside",
        "naive_max_penetration",
        "augmented_n_outside",
        "augmented_max_penetration",
    ]
    assert [int(r["step"]) for r in rows] == [0, 100, 200]
    assert (out / "comparison.png").stat().st_size > 1000
    assert (out / "comparison.mp4").stat().st_size > 1000


def test_interp_test_reports_errors(tmp_path, capsys):
    """Fig. 4: near a straight wall the distance field is linear, so the augmented reconstruction is
    exact there (to 1e-3 h, limited by the 6h corner margin), while the naive one is off by 0.1 h or more."""
    assert main(["interp-test", "--out", str(tmp_path)]) == 0
    results = {r["method"]: r for r in json.loads((tmp_path / "interp_test.json").read_text())}
    assert results["augmented"]["max_error"] < 1e-3
    assert results["naive"]["max_error"] > 0.1
    assert results["augmented"]["rms_error"] < 0.01 * results["naive"]["rms_error"]
    assert (tmp_path / "interp_test.png").stat().st_size > 1000
    assert "augmented" in capsys.readouterr().out
