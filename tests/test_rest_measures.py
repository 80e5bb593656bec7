"""The water-at-rest case's measures (issue 42) read known answers off drawn particle sets; its scene builds."""

from __future__ import annotations

import numpy as np

from augmpm.scene import Scene
from augmpm.validation import rest

H = 1.0 / 48


def lattice(x0: float, x1: float, y0: float, y1: float, per_cell: int = 4) -> np.ndarray:
    """Particles at h/√per_cell spacing, centred in their squares, filling [x0, x1] × [y0, y1] (m)."""
    d = H / np.sqrt(per_cell)
    xs = np.arange(x0 + d / 2, x1, d)
    ys = np.arange(y0 + d / 2, y1, d)
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)


def box_distance(x0: float, x1: float, y0: float):
    """The signed distance to an open-topped box's walls (negative inside), as `Simulation.wall_distance`."""

    def distance(p: np.ndarray) -> np.ndarray:
        return -np.minimum(np.minimum(p[:, 0] - x0, x1 - p[:, 0]), p[:, 1] - y0)

    return distance


def test_surface_is_the_mean_top_of_the_middle_columns():
    """Water to 20 h in a box from 6 h to 42 h at 4 per cell: the top row is a quarter cell below; one column
    raised by 1 h in the middle half (18 columns) raises the surface by h/18, one outside it not at all."""
    x = lattice(6 * H, 42 * H, 6 * H, 20 * H)
    middle = (15 * H, 33 * H)
    assert abs(rest.surface(x, H, middle) - 19.75 * H) < 1e-12
    lifted = x.copy()
    lifted[np.floor(x[:, 0] / H) == 20, 1] += H
    assert abs(rest.surface(lifted, H, middle) - (19.75 + 1 / 18) * H) < 1e-12
    lifted[np.floor(x[:, 0] / H) == 10, 1] += 5 * H
    assert abs(rest.surface(lifted, H, middle) - (19.75 + 1 / 18) * H) < 1e-12


def test_pressure_gradient_is_fitted_over_the_deep_particles_away_from_walls():
    """p = ρg·depth below 2 h and away from the walls gives ρg, whatever the shallow particles and those near
    the walls carry."""
    x = lattice(6 * H, 42 * H, 6 * H, 20 * H)
    depth = 19.75 * H - x[:, 1]
    wall = box_distance(6 * H, 42 * H, 6 * H)(x)
    p = 1000.0 * 9.81 * depth
    p[depth < 2 * H] = 1e6
    p[wall > -3 * H] = -1e6
    assert abs(rest.pressure_gradient(depth, p, wall, H) / (1000.0 * 9.81) - 1) < 1e-12


def test_blocks_of_a_uniform_lattice_agree_and_a_packed_cell_shows():
    """At 4 per cell every interior block of 4×4 cells holds 64 particles: water to 20 h in a box from 6 h to
    42 h has blocks wholly 2 h from the walls and the surface with lower-left cells from 8 h to 36 h across
    and 8 h to 13 h up (29 × 6). Four extra particles in cell (21, 9) lie in 4 × 2 of them."""
    x = lattice(6 * H, 42 * H, 6 * H, 20 * H)
    walls = box_distance(6 * H, 42 * H, 6 * H)
    counts = rest.block_counts(x, H, 19.75 * H, walls)
    assert len(counts) == 29 * 6 and (counts == 64).all()
    assert rest.packing_deviation(counts) == 0.0
    extra = np.array([[21.1 * H, 9.1 * H], [21.3 * H, 9.1 * H], [21.1 * H, 9.3 * H], [21.3 * H, 9.3 * H]])
    counts = rest.block_counts(np.vstack([x, extra]), H, 19.75 * H, walls)
    assert len(counts) == 174 and (counts == 68).sum() == 8
    mean = 64 + 4 * 8 / 174
    assert abs(rest.packing_deviation(counts) - (68 - mean) / mean) < 1e-12
    assert np.isnan(rest.packing_deviation(np.zeros(0, dtype=int)))


def test_scene_pours_to_the_level_and_passes_the_density_keys_through():
    """The tank is a square of side 0.75 m turned by the angle; the level is 0.3 m above its lowest corner; the
    fluid names its density estimate and relaxation time only when given; the scene validates."""
    corners = rest.tank(20.0)
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    assert np.allclose(sides, rest.SIDE)
    assert abs(rest.level(20.0) - (corners[:, 1].min() + 0.3)) < 1e-15
    assert "density_estimate" not in rest.water() and "relaxation_time" not in rest.water()
    fluid = rest.water("packing", 0.2)
    assert fluid["density_estimate"] == "packing" and fluid["relaxation_time"] == 0.2
    spec = rest.scene(20.0, density_estimate="grid")
    assert spec["bodies"][0]["fill"] and spec["bodies"][0]["max"][1] == rest.level(20.0)
    assert Scene.from_dict(spec).bodies[0].material.density_estimate == "grid"
