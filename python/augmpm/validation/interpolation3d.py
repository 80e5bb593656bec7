"""Case: the interpolation test in 3D. Signed-distance fields next to a plane whose normal lies in no
coordinate plane (tilted θ from vertical, the frame of the 3D incline case) and around a sphere are
reconstructed from their values at the grid points, as in 2D (:mod:`augmpm.validation.interpolation`):
naive, every node of the 3×3×3 stencil, nodes beyond the wall holding the wall value 0; augmented, the
included nodes and the boundary points, which hold the field's value on the wall. Errors are taken within 2h
of the wall, away from the domain box."""

from __future__ import annotations

import json

import numpy as np

from augmpm.validation.common import METHODS, SECOND_ORDER, observed_order
from augmpm.validation.incline3d import plane_frame
from augmpm.validation.interpolation import reconstruction_errors
from augmpm.validation.records import Record

#: The sphere (an obstacle): centre and radius (m).
SPHERE = ((0.5, 0.5, 0.5), 0.25)
#: A point of the plane (m).
POINT = (0.5, 0.45, 0.5)


def _walls(kind: str, angle: float, resolution: int) -> tuple[str, callable]:
    """Scene JSON with the wall, and its signed-distance field (positive in the material)."""
    if kind == "sphere":
        centre, radius = SPHERE
        walls = [{"type": "sphere", "center": list(centre), "radius": radius}]

        def field(x):
            return np.linalg.norm(x - np.asarray(centre), axis=1) - radius
    else:
        n, _ = plane_frame(angle)
        walls = [{"type": "plane", "point": list(POINT), "normal": n.tolist()}]

        def field(x):
            return (x - np.asarray(POINT)) @ n

    scene = {
        "gravity": [0.0, 0.0, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": resolution},
        "time": {"dt": 1.0, "steps": 0, "output_interval": 1},
        "walls": walls,
    }
    return json.dumps(scene), field


def errors(kind: str, angle: float, method: str, resolution: int, samples: int = 20000) -> tuple[float, float]:
    """RMS and max absolute error (m) of the reconstruction within 2h of the wall, inside [0.15, 0.85]³."""
    scene, field = _walls(kind, angle, resolution)
    rng = np.random.default_rng(1)
    query = 0.15 + 0.7 * rng.random((samples * 40, 3))
    d = field(query)
    query = query[(d > 0) & (d < 2.0 / resolution)][:samples]
    return reconstruction_errors(scene, method, field, query)


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    """The plane at each tilt of `angles` but 0° (16 to 128 cells; quick: to 64) and the sphere (its observed
    order over the same levels, as in 2D)."""
    levels = [16, 32, 64] if quick else [16, 32, 64, 128]
    records, data = [], {}
    cases = [("linear", a) for a in angles if a > 0] + [("sphere", 0.0)]
    for kind, angle in cases:
        for method in METHODS:
            measured = [errors(kind, angle, method, n) for n in levels]
            rms = [e[0] for e in measured]
            data[(kind, angle, method)] = (levels, rms)
            name = f"interpolation3d_{kind}"
            records.append(Record(name, method, angle, levels[-1], "rms_error_over_h", rms[-1] * levels[-1], None))
            if kind == "linear":
                # A linear field is reproduced exactly by the augmented grid: the error is round-off.
                worst = measured[-1][1]
                records.append(Record(name, method, angle, levels[-1], "max_error_over_h", worst * levels[-1], 1e-8))
            else:
                order = observed_order([1.0 / n for n in levels], rms)
                records.append(Record(name, method, angle, levels[-1], "observed_order", order, SECOND_ORDER, ">="))
    return records, data
