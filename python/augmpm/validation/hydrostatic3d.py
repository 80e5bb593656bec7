"""Case: a fluid column at rest in a tilted box, in 3D: p = ρg(y_s − y), nothing leaks. The container is a
cube turned by the case's angle about (1, 0.2, 0.6), an axis in no coordinate plane, so that the free
surface meets its faces, edges and corners at angles the grid has nowhere; the water is the part of the
cube below y = 0.45 m (4 particles per cell), seeded at rest, and settles under a viscosity that damps its sloshing."""

from __future__ import annotations

import math

import numpy as np

from augmpm.validation.common import METHODS, CaseFailed, fluid, simulate
from augmpm.validation.hydrostatic import RHO, G, layer_pressures
from augmpm.validation.records import Record

#: The container: a cube of this edge (m) about (0.5, 0.5, 0.5), turned about this axis (inside the domain at any turn).
EDGE = 0.55
AXIS = [1.0, 0.2, 0.6]
#: The water's height above the domain's floor (m): its depth is that less the cube's lowest point.
FILL = 0.45
#: The cube's turn (°); one angle (a 3D run costs what a dozen 2D ones do).
ANGLE = 30.0


def _scene(angle: float, resolution: int) -> tuple[dict, dict]:
    material = fluid(RHO, 10 * math.sqrt(G * 0.35), 50.0)
    scene = {
        "name": f"hydrostatic3d_{angle:g}deg",
        "seed": 3,
        "gravity": [0.0, -G, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [
            {"type": "box", "center": [0.5, 0.5, 0.5], "size": [EDGE] * 3, "axis": AXIS, "angle": math.radians(angle)}
        ],
        "bodies": [
            {
                "shape": "box",
                "min": [0.0, 0.0, 0.0],
                "max": [1.0, FILL, 1.0],
                "fill": True,
                "material": material,
                "seeding": {"per_cell": 4},
            }
        ],
    }
    return scene, material


def run(quick: bool, angles: list[float] = [ANGLE]) -> tuple[list[Record], dict]:  # noqa: B006 (read only)
    """The column at each angle of `angles` (the cube's turn), both methods; 32 cells (quick) or 40, for
    0.5 s (quick) or 0.8 s."""
    resolution = 32 if quick else 40
    t_end = 0.5 if quick else 0.8
    h = 1.0 / resolution
    records, data = [], {}
    for angle in angles:
        scene, mat = _scene(angle, resolution)
        for method in METHODS:
            outside = []

            def sample(sim, outside=outside):
                outside.append(sim.metrics()["n_outside"])
                x = sim.positions
                return x, sim.densities, np.linalg.norm(sim.velocities, axis=1).max(), sim.wall_distance(x)

            try:
                samples, _ = simulate(scene, method, list(np.linspace(t_end / 5, t_end, 5)), sample)
            except CaseFailed as e:
                records.append(Record.failed_run("hydrostatic3d", method, angle, resolution, e))
                continue
            x, rho, vmax, wall = samples[-1]
            y_l, residual, pm_l, residual_mean, y_s = layer_pressures(x[:, 1], rho, wall, mat, h)
            depth = y_s - float(x[wall < 0, 1].min())  # of the particles inside the walls
            data[(method, angle)] = (y_l, pm_l, y_s)
            scale = RHO * G * depth

            def rec(metric: str, value: float, tol: float, m: str = method, a: float = angle) -> None:
                records.append(Record("hydrostatic3d", m, a, resolution, metric, float(value), tol))

            rec("pressure_rms_error_over_rho_g_H", np.sqrt(np.mean(residual**2)) / scale, 0.02)
            rec("particle_pressure_rms_error_over_rho_g_H", np.sqrt(np.mean(residual_mean**2)) / scale, 0.02)
            rec("max_speed_over_sqrt_gH_at_end", vmax / math.sqrt(G * depth), 0.02)
            rec("particles_outside_max", max(outside), 0.0)
    return records, data
