"""Case: a ball on a frictionless plane at a compound angle, in 3D. The plane's normal lies in no coordinate
plane (tilted θ from vertical, its downhill direction 35° from x towards z); an elastic ball on it (full slip:
it slides without rolling) accelerates at g·sinθ down the plane and stays out of it."""

from __future__ import annotations

import math

import numpy as np

from augmpm._core import SimulationError
from augmpm.scene import Scene3
from augmpm.simulation import Simulation
from augmpm.validation.common import METHODS, CaseFailed
from augmpm.validation.records import Record

G = 9.81
RADIUS = 0.06  # m
#: The downhill direction's angle from x towards z, in the horizontal plane.
AZIMUTH = math.radians(35.0)


def plane_frame(angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The plane's normal (up out of it) and its downhill direction, for a tilt of `angle` degrees."""
    theta = math.radians(angle)
    d = np.array([math.cos(AZIMUTH), 0.0, math.sin(AZIMUTH)])
    n = math.cos(theta) * np.array([0.0, 1.0, 0.0]) + math.sin(theta) * d
    t = math.cos(theta) * d - math.sin(theta) * np.array([0.0, 1.0, 0.0])
    return n, t


def _scene(angle: float, resolution: int) -> tuple[dict, np.ndarray]:
    """The scene, and the plane's downhill direction."""
    h = 1.0 / resolution
    n, t = plane_frame(angle)
    point = np.array([0.5, 0.45, 0.5])
    centre = point - 0.22 * t + n * (RADIUS + 0.1 * h)
    scene = {
        "name": f"incline3d_{angle:g}deg",
        "seed": 5,
        "gravity": [0.0, -G, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "slip",
        "walls": [{"type": "plane", "point": point.tolist(), "normal": n.tolist()}],
        "bodies": [
            {
                "shape": "sphere",
                "center": centre.tolist(),
                "radius": RADIUS,
                "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 2e6, "poisson_ratio": 0.3},
            }
        ],
    }
    return scene, t


def _slide(scene: dict, t: np.ndarray, method: str, times: list[float]) -> tuple[list[float], int]:
    """The ball's mass-weighted distance down the plane (m) at `times`, and the most particles past a wall at
    any of them; raises CaseFailed."""
    sim = Simulation(Scene3.from_dict(scene), method)
    s, outside = [], 0
    for when in times:
        try:
            sim.step(max(0, round((when - sim.time) / sim.dt)))
        except SimulationError as e:
            raise CaseFailed(str(e), sim.time) from None
        s.append(float(np.average(sim.positions @ t, weights=sim.masses)))
        outside = max(outside, sim.metrics()["n_outside"])
    return s, outside


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    """The ball at each tilt of `angles` (but 0°) for 0.3 m of slide; 24 cells per metre (quick) or 48."""
    resolution = 24 if quick else 48
    records, curves = [], {}
    for angle in [a for a in angles if a > 0]:
        a_exact = G * math.sin(math.radians(angle))
        t_end = math.sqrt(2 * 0.3 / a_exact)
        times = list(np.linspace(0.15 * t_end, t_end, 16))
        scene, t = _scene(angle, resolution)
        for method in METHODS:
            try:
                s, outside = _slide(scene, t, method, times)
            except CaseFailed as e:
                records.append(Record.failed_run("incline3d", method, angle, resolution, e))
                continue
            accel = 2 * np.polyfit(times, s, 2)[0]
            curves[(method, angle)] = (times, s, a_exact)
            records.append(
                Record("incline3d", method, angle, resolution, "acceleration_rel_error", abs(accel / a_exact - 1), 0.01)
            )
            records.append(Record("incline3d", method, angle, resolution, "particles_outside_max", outside, 0.0))
    return records, curves
