"""The validation's watch on the fluids' J inside the water (augmpm.validation.bounds)."""

from __future__ import annotations

import numpy as np

from augmpm.scene import load_scene
from augmpm.simulation import Simulation
from augmpm.validation import bounds, rigid


def _water_at_rest(steps: int = 200) -> Simulation:
    """Water 0.3 m deep in the buoyancy case's tank (floor at an angle to the grid, 32 cells), a box above it."""
    sim = Simulation(rigid.tank([rigid.FLOATING["box"]], 32, 1.0), "augmented")
    sim.step(steps)
    return sim


def test_the_watched_particles_lie_two_cells_inside_the_water():
    """Every particle the watch takes lies at least 2 h inside the walls and, its cell two cells below the top
    particle's at least, more than h below the highest particle; together they are a good part of the water
    (water 9 cells deep: 428 of 934 measured; at least a third asserted); their J is the engine's."""
    sim = _water_at_rest()
    h = sim.cell_size
    x = sim.positions
    chosen = bounds.interior_mask(sim)
    assert chosen.sum() >= sim.num_particles / 3
    assert np.all(sim.wall_distance(x[chosen]) <= -2 * h)
    assert x[chosen, 1].max() < x[:, 1].max() - h
    assert np.array_equal(bounds.interior_volume_ratios(sim), sim.particle_fields()["J"][chosen])


def test_a_swollen_particle_inside_the_water_fails_the_check_and_one_at_the_surface_does_not():
    """A J of 3 set on a watched particle makes the watched maximum 3, which fails the check (≤ 2); set on the
    highest particle instead, it is not watched and the check passes."""
    for inside in (True, False):
        sim = _water_at_rest()
        k = int(np.flatnonzero(bounds.interior_mask(sim))[0] if inside else sim.positions[:, 1].argmax())
        state = sim.checkpoint()
        state["jp"] = state["jp"].copy()
        state["jp"][k] = 3.0
        sim.restore(state)
        bounds.reset()
        bounds.watch(sim, "augmented")
        high = next(r for r in bounds.records("case") if r.metric == "interior_fluid_J_max")
        assert (high.passed is False) == inside, high
        assert (high.value == 3.0) == inside
    bounds.reset()


def test_a_variant_density_is_reported_apart_and_not_judged():
    """Runs with another density than the default, which cases run beside it, are recorded as
    `<case>_<density>` with no tolerance, apart from the default's judged records."""
    bounds.reset()
    bounds.watch(_water_at_rest(), "augmented")
    scene = rigid.tank([rigid.FLOATING["box"]], 32, 1.0, {**rigid.WATER, "density_estimate": "packing"})
    sim = Simulation(scene, "augmented")
    sim.step(200)
    bounds.watch(sim, "augmented")
    by_case = {(r.case, r.metric): r for r in bounds.records("case")}
    bounds.reset()
    metrics = ("interior_fluid_J_min", "interior_fluid_J_max")
    assert set(by_case) == {(case, metric) for case in ("case", "case_packing") for metric in metrics}
    assert by_case[("case", "interior_fluid_J_max")].tolerance == bounds.HIGH
    assert by_case[("case_packing", "interior_fluid_J_max")].tolerance is None


def test_nothing_is_recorded_before_a_step_or_without_a_fluid():
    """Before the first step J is not known yet, and a scene without fluid (the shipped sand column) records
    nothing."""
    sim = Simulation(rigid.tank([rigid.FLOATING["box"]], 32, 1.0), "augmented")
    assert not bounds.interior_mask(sim).any()
    sand = Simulation(load_scene("sand/column_collapse"), "augmented")
    sand.step(2)
    bounds.reset()
    bounds.watch(sim, "augmented")
    bounds.watch(sand, "augmented")
    assert bounds.records("case") == []


def test_the_shipped_scene_check_runs_a_scene_and_reports_its_range(capsys):
    """`python -m augmpm.validation.bounds` over the first 3 output steps of the floating bodies: J inside the water
    within [0.5, 2] (0.98–1.00 measured), exit 0, one line naming the scene and the outputs; with the packing
    density as well."""
    assert bounds.main(["rigid/floating_bodies", "--outputs", "3"]) == 0
    assert bounds.main(["rigid/floating_bodies", "--outputs", "3", "--density-estimate", "packing"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all(line.startswith("rigid/floating_bodies: J inside the water") for line in lines)
    assert all("over 3 outputs" in line and "NOT" not in line for line in lines)
    low, high, outputs = bounds.shipped("rigid/floating_bodies", outputs=3)
    assert outputs == 3 and bounds.LOW <= low <= high <= bounds.HIGH
