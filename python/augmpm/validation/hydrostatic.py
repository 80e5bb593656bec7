"""Case 5: a fluid column at rest in a container with inclined side walls: p = ρg(H − y), nothing leaks."""

from __future__ import annotations

import math

import numpy as np

from augmpm.validation.common import METHODS, CaseFailed, fluid, simulate
from augmpm.validation.records import Record

G = 9.81
RHO = 1000.0
DEPTH = 0.25  # fluid depth (m)
BOTTOM = 0.3  # floor width (m)
WALL_HEIGHT = 0.3  # m


def _scene(angle: float, resolution: int) -> tuple[dict, dict]:
    h = 1.0 / resolution
    floor = 0.1 + 0.3 * h  # off the grid lines
    spread = math.tan(math.radians(angle))
    xl, xr = 0.5 - BOTTOM / 2, 0.5 + BOTTOM / 2
    container = [[xl, floor], [xr, floor], [xr + WALL_HEIGHT * spread, floor + WALL_HEIGHT],
                 [xl - WALL_HEIGHT * spread, floor + WALL_HEIGHT]]  # fmt: skip
    eps = 1e-6
    column = [[xl + eps, floor + eps], [xr - eps, floor + eps], [xr + DEPTH * spread - eps, floor + DEPTH],
              [xl - DEPTH * spread + eps, floor + DEPTH]]  # fmt: skip
    material = fluid(RHO, 10 * math.sqrt(G * DEPTH), 50.0)
    scene = {
        "name": f"hydrostatic_{angle:g}deg",
        "seed": 3,
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [{"type": "polygon", "vertices": container}],
        "bodies": [{"shape": "polygon", "vertices": column, "material": material, "seeding": {"per_cell": 4}}],
    }
    return scene, material


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    resolution = 64 if quick else 128
    t_end = 0.6 if quick else 1.0
    h = 1.0 / resolution
    records, data = [], {}
    for angle in angles:
        scene, mat = _scene(angle, resolution)
        for method in METHODS:
            outside = []

            def sample(sim, mat=mat, outside=outside):
                outside.append(sim.metrics()["n_outside"])
                x, rho = sim.positions, sim.densities
                p = np.maximum(mat["stiffness"] * ((rho / mat["density"]) ** mat["gamma"] - 1), mat["min_pressure"])
                return x, p, np.abs(sim.velocities).max(), sim.wall_distance(x)

            try:
                samples, _ = simulate(scene, method, list(np.linspace(t_end / 6, t_end, 6)), sample)
            except CaseFailed as e:
                records.append(Record.failed_run("hydrostatic", method, angle, resolution, e))
                continue
            x, p, vmax, wall = samples[-1]
            # The free surface height is fitted: p = ρg(y_s − y) over the bulk (2h from walls and surface).
            surface = np.percentile(x[:, 1], 99.5)
            bulk = (wall < -2 * h) & (x[:, 1] < surface - 2 * h)
            y_s = float(np.mean(x[bulk, 1] + p[bulk] / (RHO * G)))
            residual = p[bulk] - RHO * G * (y_s - x[bulk, 1])
            data[(method, angle)] = (x[bulk, 1], p[bulk], y_s)
            scale = RHO * G * DEPTH
            rec = lambda metric, value, tol, m=method, a=angle: records.append(  # noqa: E731
                Record("hydrostatic", m, a, resolution, metric, float(value), tol)
            )
            rec("pressure_rms_error_over_rho_g_H", np.sqrt(np.mean(residual**2)) / scale, 0.02)
            rec("max_speed_over_sqrt_gH_at_end", vmax / math.sqrt(G * DEPTH), 0.02)
            rec("particles_outside_max", max(outside), 0.0)
    return records, data
