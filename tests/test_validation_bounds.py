"""The validation's watch on the fluids' J inside the water (augmpm.validation.bounds)."""

from __future__ import annotations

import numpy as np

from augmpm.simulation import Simulation
from augmpm.validation import bounds, rigid


def _water_at_rest(steps: int = 200) -> Simulation:
    """Water 0.3 m deep in the buoyancy case's tank (floor at an angle to the grid, 32 cells), a box above it."""
    sim = Simulation(rigid.tank([rigid.FLOATING["box"]], 32, 1.0), "augmented")
    sim.step(steps)
    return sim


def test_the_watched_particles_lie_two_cells_inside_the_water():
    """Every particle the watch takes lies at least 2 h inside the walls and 2 h below the highest particle,
    and together they are a good part of the water (water 9 cells deep: 428 of 934 measured; at least a third
    asserted); their J is the engine's."""
    sim = _water_at_rest()
    h = sim.cell_size
    x, j = sim.positions, sim.particle_fields()["J"]
    watched = bounds.interior_volume_ratios(sim)
    chosen = np.isin(j, watched)
    assert chosen.sum() >= sim.num_particles / 3
    assert np.all(sim.wall_distance(x[chosen]) <= -2 * h)
    assert x[chosen, 1].max() <= x[:, 1].max() - 2 * h


def test_a_swollen_particle_inside_the_water_fails_the_check_and_one_at_the_surface_does_not():
    """A J of 3 set on a watched particle makes the watched maximum 3, which fails the check (≤ 2); set on the
    highest particle instead, it is not watched and the check passes."""
    for inside in (True, False):
        sim = _water_at_rest()
        j = sim.particle_fields()["J"]
        k = int(
            np.flatnonzero(np.isin(j, bounds.interior_volume_ratios(sim)))[0]
            if inside
            else sim.positions[:, 1].argmax()
        )
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


def test_nothing_is_recorded_before_a_step_or_without_a_fluid():
    """Before the first step J is not known yet, and a case without fluid records nothing."""
    sim = Simulation(rigid.tank([rigid.FLOATING["box"]], 32, 1.0), "augmented")
    assert bounds.interior_volume_ratios(sim).size == 0
    bounds.reset()
    bounds.watch(sim, "augmented")
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
