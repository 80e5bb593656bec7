"""Case 4: an elastic block on a frictionless (full-slip) incline accelerates at g·sinθ and stays out of the wall."""

from __future__ import annotations

import math

import numpy as np

from augmpm.validation.common import METHODS, CaseFailed, Frame, simulate
from augmpm.validation.records import Record

G = 9.81
BLOCK = (0.12, 0.06)  # length along the incline, height (m)


def _scene(angle: float, resolution: int) -> tuple[dict, Frame]:
    h = 1.0 / resolution
    drop = 0.9 * math.tan(math.radians(angle))
    top = (0.05, 0.05 + drop)
    frame = Frame(top, -angle)  # t runs down the incline, n points up out of it
    container = [[0.05, 0.05 + drop], [0.95, 0.05], [0.95, 0.97], [0.05, 0.97]]
    s0 = 0.1
    scene = {
        "name": f"incline_{angle:g}deg",
        "seed": 5,
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [{"type": "polygon", "vertices": container}],
        "bodies": [
            {
                "shape": "polygon",
                "vertices": frame.rect(s0, s0 + BLOCK[0], 0.1 * h, 0.1 * h + BLOCK[1]),
                "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 2e6, "poisson_ratio": 0.3},
                "seeding": {"per_cell": 4},
            }
        ],
    }
    return scene, frame


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    resolution = 64 if quick else 128
    records, curves = [], {}
    for angle in [a for a in angles if a > 0]:
        a_exact = G * math.sin(math.radians(angle))
        t_end = math.sqrt(2 * 0.35 / a_exact)
        times = list(np.linspace(0.15 * t_end, t_end, 16))
        scene, frame = _scene(angle, resolution)
        for method in METHODS:
            outside = []

            def sample(sim, frame=frame, outside=outside):
                s, _ = frame.coords(sim.positions)
                outside.append(sim.metrics()["n_outside"])
                return float(np.average(s, weights=sim.masses))

            try:
                s, _ = simulate(scene, method, times, sample)
            except CaseFailed as e:
                records.append(Record.failed_run("incline", method, angle, resolution, e))
                continue
            fit = np.polyfit(times, s, 2)
            accel = 2 * fit[0]
            curves[(method, angle)] = (times, s, a_exact)
            records.append(
                Record("incline", method, angle, resolution, "acceleration_rel_error", abs(accel / a_exact - 1), 0.01)
            )
            records.append(Record("incline", method, angle, resolution, "particles_outside_max", max(outside), 0.0))
    return records, curves
