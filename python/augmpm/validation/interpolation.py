"""Case 7: reconstruct signed-distance fields near inclined and curved walls from their values at the grid
points (the paper's Fig. 4 idea), and the error's convergence under refinement.

Naive: every node of the 3×3 stencil, nodes beyond the wall holding the wall value 0. Augmented: the included
nodes plus the boundary points, which hold the field's value on the wall. Errors are taken within 2h of the
wall, away from other walls and corners.
"""

from __future__ import annotations

import json
import math

import numpy as np

from augmpm import _core
from augmpm.validation.common import METHODS, SECOND_ORDER, observed_order
from augmpm.validation.records import Record

CIRCLE = ((0.5, 0.5), 0.25)


def _walls(kind: str, angle: float, resolution: int) -> tuple[str, callable, callable]:
    """Scene JSON with the walls, the field, and the mask of query points judged."""
    if kind == "circle":
        (cx, cy), r = CIRCLE
        walls = [{"type": "circle", "center": [cx, cy], "radius": r, "side": "outside"}]

        def field(x):
            return np.hypot(x[:, 0] - cx, x[:, 1] - cy) - r

        def judged(x, h):
            d = field(x)
            return (d > 0) & (d < 2 * h)
    else:
        t = math.tan(math.radians(angle))
        y0 = 0.1
        x1 = 0.05 + (min(0.9, 0.8 / t) if t > 0 else 0.9)
        walls = [{"type": "polygon", "vertices": [[0.05, y0], [x1, y0 + (x1 - 0.05) * t], [x1, 0.97], [0.05, 0.97]]}]
        n = np.array([-math.sin(math.radians(angle)), math.cos(math.radians(angle))])

        def field(x):
            return (x - np.array([0.05, y0])) @ n

        def judged(x, h):
            d = field(x)
            return (d > 0) & (d < 2 * h) & (x[:, 0] > 0.05 + 0.15) & (x[:, 0] < x1 - 0.15)

    scene = {
        "gravity": [0.0, 0.0],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"dt": 1.0, "steps": 0, "output_interval": 1},
        "walls": walls,
    }
    return json.dumps(scene), field, judged


def reconstruction_errors(scene: str, method: str, field: callable, query: np.ndarray) -> tuple[float, float]:
    """RMS and max absolute error (m) at `query` of the field reconstructed on the grid of `scene` (JSON, 2D
    or 3D) from its values at the grid points: naive, nodes beyond the wall holding the wall value 0;
    augmented, the included nodes and the boundary points, which hold the field's value on the wall."""
    grid = _core.Grid(scene, method)
    nodes = grid.nodes
    inside = grid.wall_distance(nodes) < 0
    node_values = np.where(inside, field(nodes), 0.0)
    values = np.concatenate([node_values, field(grid.boundary_points)]) if method == "augmented" else node_values
    recon, _ = grid.interpolate(values, np.ascontiguousarray(query))
    err = np.abs(recon - field(query))
    return float(np.sqrt(np.mean(err**2))), float(err.max())


def errors(kind: str, angle: float, method: str, resolution: int, samples: int = 20000) -> tuple[float, float]:
    """RMS and max absolute error (m) of the reconstruction in the judged band."""
    scene, field, judged = _walls(kind, angle, resolution)
    rng = np.random.default_rng(1)
    query = rng.random((samples * 20, 2))
    query = query[judged(query, 1.0 / resolution)][:samples]
    return reconstruction_errors(scene, method, field, query)


def run(quick: bool, angles: list[float]) -> tuple[list[Record], dict]:
    levels = [16, 32, 64] if quick else [16, 32, 64, 128]
    records, data = [], {}
    cases = [("linear", a) for a in angles] + [("circle", 0.0)]
    for kind, angle in cases:
        for method in METHODS:
            rms = [errors(kind, angle, method, n)[0] for n in levels]
            worst = errors(kind, angle, method, levels[-1])[1]
            data[(kind, angle, method)] = (levels, rms)
            name = f"interpolation_{kind}"
            records.append(Record(name, method, angle, levels[-1], "rms_error_over_h", rms[-1] * levels[-1], None))
            if kind == "linear":
                # A linear field is reproduced exactly by the augmented grid: the error is round-off.
                records.append(Record(name, method, angle, levels[-1], "max_error_over_h", worst * levels[-1], 1e-8))
            else:
                order = observed_order([1.0 / n for n in levels], rms)
                records.append(Record(name, method, angle, levels[-1], "observed_order", order, SECOND_ORDER, ">="))
    return records, data
