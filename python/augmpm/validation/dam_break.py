"""Case 6: dam break on a horizontal floor; surge front against Martin & Moyce (1952).

A column of width a and height 2a collapses along a floor; Z = x_front/a against T = t·sqrt(2g/a).
At angles other than 0° the whole tank and gravity are turned against the grid.
"""

from __future__ import annotations

import math

import numpy as np

from augmpm.validation import analytic
from augmpm.validation.common import METHODS, CaseFailed, Frame, fluid, simulate
from augmpm.validation.records import Record

G = 9.81
A = 0.12  # column width (m)


def _scene(angle: float, cells: int) -> tuple[dict, Frame]:
    h = A / cells
    resolution = round(1.0 / h)
    a = math.radians(angle)
    frame = Frame((0.05 + 3 * A * math.sin(a), 0.05), angle)
    eps = 1e-6
    g = -G * frame.n
    scene = {
        "name": f"dam_break_{angle:g}deg",
        "seed": 9,
        "gravity": [float(g[0]), float(g[1])],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.3, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [{"type": "polygon", "vertices": frame.rect(0.0, 7 * A, 0.0, 3 * A)}],
        "bodies": [
            {
                "shape": "polygon",
                "vertices": frame.rect(eps, A, eps, 2 * A),
                "material": fluid(1000.0, 10 * math.sqrt(4 * G * A), 0.05),
                "seeding": {"per_cell": 4},
            }
        ],
    }
    return scene, frame


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    cells = 12 if quick else 24
    t_exp, z_exp = analytic.martin_moyce(analytic.MARTIN_MOYCE)
    judged = (t_exp <= 5.0) & (t_exp >= 0.8)
    scale = math.sqrt(2 * G / A)
    big_t = np.arange(0.5, 5.01, 0.25)
    records, curves = [], {}
    for angle in angles:
        scene, frame = _scene(angle, cells)
        for method in METHODS:

            def sample(sim, frame=frame):
                s, _ = frame.coords(sim.positions)
                return float(np.percentile(s, 99.5)) / A

            try:
                z, sim = simulate(scene, method, list(big_t / scale), sample)
            except CaseFailed as e:
                records.append(Record.failed_run("dam_break", method, angle, cells, e))
                continue
            curves[(method, angle)] = (big_t, np.array(z))
            z_at = np.interp(t_exp[judged], big_t, z)
            err = np.max(np.abs(z_at - z_exp[judged]) / z_exp[judged])
            records.append(Record("dam_break", method, angle, cells, "front_max_rel_error_T_le_5", float(err), 0.10))
            records.append(
                Record("dam_break", method, angle, cells, "particles_outside_end", sim.metrics()["n_outside"], None)
            )
    return records, {"curves": curves, "experiment": (t_exp, z_exp)}
