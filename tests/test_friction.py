"""Coulomb friction on separate walls: bodies on a rough wall can roll and can lift off it (both wall
treatments); friction applies to separate walls only."""

from __future__ import annotations

import math

import numpy as np
import pytest

import augmpm
from augmpm.validation.common import Frame

G = 9.81


def _disk_on_incline(angle: float, resolution: int, friction: float) -> tuple[dict, Frame, float]:
    theta = math.radians(angle)
    drop = 0.9 * math.tan(theta)
    frame = Frame((0.05, 0.05 + drop), -angle)  # t down the incline, n up out of it
    radius = 0.05
    centre = np.asarray(frame.origin) + frame.t * 0.15 + frame.n * (radius + 0.1 / resolution)
    scene = {
        "gravity": [0.0, -G],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "separate",
        "walls": [
            {
                "type": "polygon",
                "vertices": [[0.05, 0.05 + drop], [0.95, 0.05], [0.95, 0.97], [0.05, 0.97]],
                "friction": friction,
            }
        ],
        "bodies": [
            {
                "shape": "circle",
                "center": [float(centre[0]), float(centre[1])],
                "radius": radius,
                "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 2e6, "poisson_ratio": 0.3},
            }
        ],
    }
    return scene, frame, radius


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_a_disk_rolls_down_a_rough_incline(method):
    """A uniform disk rolling without slipping down a 30° incline accelerates at (2/3) g sinθ = 3.27 m/s²,
    not at g sinθ = 4.91 m/s² as it slides on a frictionless one: on a wall with infinite friction it rolls
    (within 5%, at 128 cells: the disk is 13 cells across), spinning at ω ≥ 0.7 v/R, and stays out of it."""
    scene, frame, radius = _disk_on_incline(30.0, 128, math.inf)
    sim = augmpm.Simulation(augmpm.Scene.from_dict(scene), method)
    times, along, spin = [], [], []
    for t in np.linspace(0.1, 0.5, 9):
        sim.step(max(0, round(t / sim.dt) - sim.steps_done))
        x, v, m = sim.positions, sim.velocities, sim.masses
        xc, vc = np.average(x, axis=0, weights=m), np.average(v, axis=0, weights=m)
        r, u = x - xc, v - vc
        spin.append(np.sum(m * (r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0])) / np.sum(m * (r**2).sum(1)))
        times.append(sim.time)
        along.append(float(frame.coords(xc[None, :])[0][0]))
        assert sim.metrics()["n_outside"] == 0
    accel = 2 * np.polyfit(times, along, 2)[0]
    rolling = 2 / 3 * G * math.sin(math.radians(30.0))
    assert abs(accel / rolling - 1) < 0.05, f"{accel:.4f} m/s² vs {rolling:.4f} m/s² rolling"
    speed = np.gradient(along, times)[-1]
    assert -spin[-1] / (speed / radius) > 0.7, "the disk slides instead of rolling"


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_a_body_lifts_off_a_rough_floor_but_not_a_sticky_one(method):
    """Thrown up at (0.5, 1) m/s from a floor with infinite friction, a block leaves it on its ballistic path:
    after 0.05 s its lowest point is at 0.001 + 0.05 − ½ g 0.05² = 0.0388 m (within a tenth of a cell) and it
    has moved 0.025 m sideways. A sticky floor holds it (its lowest point stays within a tenth of a cell)."""
    h = 1 / 64
    for condition, friction in (("separate", "inf"), ("sticky", None)):
        scene = {
            "gravity": [0.0, -G],
            "grid": {"domain": [1.0, 1.0], "resolution": 64},
            "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
            "wall_condition": condition,
            **({"wall_friction": friction} if friction else {}),
            "bodies": [
                {
                    "shape": "box",
                    "min": [0.4, 0.001],
                    "max": [0.6, 0.1],
                    "velocity": [0.5, 1.0],
                    "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 2e5, "poisson_ratio": 0.3},
                }
            ],
        }
        sim = augmpm.Simulation(augmpm.Scene.from_dict(scene), method)
        x0 = sim.positions[:, 0].mean()
        sim.step(round(0.05 / sim.dt))
        lowest = sim.positions[:, 1].min()
        if condition == "separate":
            t = sim.time
            assert abs(lowest - (0.001 + t - 0.5 * G * t * t)) < 0.1 * h, lowest
            assert abs(sim.positions[:, 0].mean() - x0 - 0.5 * t) < 0.1 * h
        else:
            assert lowest < 0.001 + 0.1 * h, lowest


def test_friction_acts_on_separate_walls_only(small_scene):
    """A wall that names a friction coefficient must be a separate wall: the scene is refused naming the key."""
    small_scene["walls"][0]["friction"] = 0.3
    small_scene["walls"][0]["condition"] = "slip"
    with pytest.raises(augmpm.SceneError) as err:
        augmpm.Scene.from_dict(small_scene)
    assert str(err.value) == "walls[0].friction: friction acts on separate walls; this wall is slip"
    small_scene["walls"][0]["condition"] = "separate"
    small_scene["walls"][0]["friction"] = "inf"
    assert augmpm.Scene.from_dict(small_scene).walls[0].friction == math.inf


@pytest.mark.parametrize(("method", "mu"), [("augmented", 0.3), ("naive", 0.3), ("augmented", 0.7)])
def test_a_block_on_a_rough_plane_at_a_compound_angle_in_3d(method, mu):
    """In 3D, an elastic block (a cube mesh turned to lie flat) on a separate plane tilted 30° whose normal
    lies in no coordinate plane: with μ = 0.3 < tan 30° it slides at g(sinθ − μ cosθ) within 1% (0.02–0.03% at
    32 cells when measured); with μ = 0.7 > tan 30° it stays (less than 0.01 cell in 1 s); nothing enters
    the plane."""
    from augmpm.validation import incline3d

    angle, res = 30.0, 32
    n, t = incline3d.plane_frame(angle)
    point = np.array([0.5, 0.45, 0.5])
    edge = 0.1
    cube = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], dtype=float) - 0.5
    quads = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]]
    triangles = [tri for q in quads for tri in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])]
    axis = np.cross([0.0, 1.0, 0.0], n)  # turns y onto the plane's normal
    block = {
        "shape": "mesh",
        "vertices": (cube * edge).tolist(),
        "triangles": triangles,
        "position": (point - 0.2 * t + n * (edge / 2 + 0.1 / res)).tolist(),
        "axis": axis.tolist(),
        "angle": math.asin(np.linalg.norm(axis)),
        "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 2e6, "poisson_ratio": 0.3},
    }
    scene = {
        "seed": 5,
        "gravity": [0.0, -G, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": res},
        "time": {"cfl": 0.4, "steps": 1, "output_interval": 1},
        "wall_condition": "separate",
        "wall_friction": mu,
        "walls": [{"type": "plane", "point": point.tolist(), "normal": n.tolist()}],
        "bodies": [block],
    }
    theta = math.radians(angle)
    a_exact = G * (math.sin(theta) - mu * math.cos(theta))
    t_end = math.sqrt(2 * 0.25 / a_exact) if a_exact > 0 else 1.0
    times = list(np.linspace(0.15 * t_end, t_end, 16))
    s, outside = incline3d._slide(scene, t, method, times)
    assert outside == 0
    if a_exact > 0:
        assert abs(2 * np.polyfit(times, s, 2)[0] / a_exact - 1) < 0.01
    else:
        assert abs(s[-1] - s[0]) * res < 0.01
