"""Case: sand (Drucker–Prager, Klár et al. 2016) — a collapsing column's run-out and a poured heap's angle.

- ``granular_column``: a column of width L and height aL, against the back wall of a tank, collapses onto a
  floor of Coulomb friction μ = tan φ. Its run-out ΔL = L∞ − L over L is, in the planar experiments'
  linear regime (a below 1.8–2.8), λa with λ between 1.2 and 1.8: the coefficients of Lube et al. 2005
  (sand, rice, sugar) and Lajeunesse et al. 2005 (glass beads), as compiled by Lagrée, Staron & Popinet
  2011 (J. Fluid Mech. 686, eq. (3.1)). Judged: λ = ΔL/(aL) within that range. L∞ is the deposit's toe:
  the farthest point, counted from the back wall without a gap, where the deposit's highest particle is
  at least h/2 above the floor (a single layer of particles, 4 per cell, has its centres at h/4: the
  particles that run ahead in one layer do not count).
- ``granular_heap``: sand drains from a hopper (slip walls, an orifice of 0.04 m: 5 cells at 128 cells,
  3.8 at 96) onto a floor and piles
  up until the heap closes the orifice. A cohesionless slope stands up to the friction angle φ (the
  infinite-slope limit of Mohr–Coulomb, which the 2D cone is exactly): judged, the heap's slope within 2°
  of φ — a straight line fitted to the heap's surface between 15% and 85% of its height, on each side,
  averaged over both sides and over the run's last second.

The tank, the floor and gravity are turned together by the case's angle to the grid.
"""

from __future__ import annotations

import math

import numpy as np

from augmpm.validation.common import METHODS, CaseFailed, Frame, simulate
from augmpm.validation.records import Record

#: Gravity (m/s²) and the sand's friction angle (degrees).
G = 9.81
PHI = 30.0


def sand(friction_angle: float = PHI) -> dict:
    """The sand of both cases: Klár et al. 2016's density and stiffness (ρ = 2200 kg/m², E = 3.537e5 N/m,
    ν = 0.3), cohesionless."""
    return {
        "type": "sand",
        "density": 2200.0,
        "youngs_modulus": 3.537e5,
        "poisson_ratio": 0.3,
        "friction_angle": friction_angle,
    }


#: The column's width (m), and the published range of the run-out coefficient λ in ΔL/L = λa (a below
#: 1.8–2.8).
COLUMN_WIDTH = 0.1
RUNOUT_RANGE = (1.2, 1.8)


def column_scene(aspect: float, cells: int, angle: float) -> tuple[dict, Frame]:
    """A column of width `COLUMN_WIDTH` and height `aspect` times that, `cells` cells across its width."""
    width = COLUMN_WIDTH
    # The tank's back wall leans over the grid's left edge at an angle: move it right by its top's lean.
    frame = Frame((0.05 + 0.3 * math.sin(math.radians(angle)), 0.05), angle)
    g = -G * frame.n
    eps = 1e-6
    scene = {
        "name": f"granular_column_a{aspect:g}_{angle:g}deg",
        "seed": 3,
        "gravity": [float(g[0]), float(g[1])],
        "grid": {"domain": [1.0, 1.0], "resolution": round(cells / width)},
        "time": {"cfl": 0.5, "steps": 1, "output_interval": 1},
        "wall_condition": "separate",
        "wall_friction": math.tan(math.radians(PHI)),
        "walls": [{"type": "polygon", "vertices": frame.rect(0.0, 0.7, 0.0, 0.3)}],
        "bodies": [
            {
                "shape": "polygon",
                "vertices": frame.rect(eps, width, eps, aspect * width),
                "material": sand(),
                "seeding": {"per_cell": 4},
            }
        ],
    }
    return scene, frame


def deposit_toe(s: np.ndarray, y: np.ndarray, h: float) -> float:
    """The farthest distance from the back wall (m) up to which the deposit, in bins of h/2, is at least h/2
    thick without a gap (`s`, `y`: the particles along and above the floor, m)."""
    edges = np.arange(0.0, max(float(s.max()), 0.0) + h, h / 2)
    top = bin_tops(s, y, edges, empty=0.0)
    k = 0
    while k < len(top) and top[k] >= h / 2:
        k += 1
    return float(edges[k]) if k < len(edges) else float(edges[-1] + h / 2)


def bin_tops(s: np.ndarray, y: np.ndarray, edges: np.ndarray, empty: float) -> np.ndarray:
    """The highest `y` (m) of the particles in each bin along the floor that starts at an edge of `edges` (m;
    particles before the first edge count in the first bin, past the last in the last), `empty` where none is."""
    top = np.full(len(edges), empty)
    np.maximum.at(top, np.clip(np.digitize(s, edges) - 1, 0, len(edges) - 1), y)
    return top


def surface(s: np.ndarray, y: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """The deposit's surface: the highest particle of each bin of `width` along the floor (bin centres, tops)."""
    edges = np.arange(float(s.min()), float(s.max()) + width, width)
    top = bin_tops(s, y, edges, empty=-np.inf)
    keep = np.isfinite(top)
    return edges[keep] + width / 2, top[keep]


#: The hopper: its orifice's width (m) and height above the floor (m), its walls' half-width (m).
ORIFICE = 0.04
ORIFICE_HEIGHT = 0.15
HOPPER = 0.27


def heap_scene(resolution: int, angle: float, friction_angle: float = PHI) -> tuple[dict, Frame]:
    """Sand in a hopper above the middle of a floor; `Frame` coordinates: along the floor from the
    orifice's axis, and up from the floor (m)."""
    # Raised so that the floor stays in the grid when turned (its ends, 0.35 m either way, drop 0.175 m at 30°).
    frame = Frame((0.5, 0.2), angle)
    g = -G * frame.n
    w, oy, thick = ORIFICE / 2, ORIFICE_HEIGHT, 0.03
    # The left plate: from the orifice's edge up and out at 45°, then up; its mirror image on the right.
    plate = [(-w - 0.02, oy), (-w, oy), (-HOPPER, oy + 0.25), (-HOPPER, oy + 0.7),
             (-HOPPER - thick, oy + 0.7), (-HOPPER - thick, oy + 0.24)]  # fmt: skip
    left = [frame.to_world(s, y) for s, y in plate]
    right = [frame.to_world(-s, y) for s, y in reversed(plate)]
    e = 0.004
    top = oy + 0.22 - e
    fill = [(-w + e, oy + e), (w - e, oy + e), (w + top - oy - 2 * e, top), (-w - (top - oy) + 2 * e, top)]
    scene = {
        "name": f"granular_heap_{angle:g}deg",
        "seed": 3,
        "gravity": [float(g[0]), float(g[1])],
        "grid": {"domain": [1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.5, "steps": 1, "output_interval": 1},
        "wall_condition": "separate",
        "wall_friction": "inf",
        "walls": [
            {"type": "polygon", "vertices": frame.rect(-0.35, 0.35, 0.0, 0.9)},
            {"type": "polygon", "vertices": left, "side": "outside", "condition": "slip"},
            {"type": "polygon", "vertices": right, "side": "outside", "condition": "slip"},
        ],
        "bodies": [
            {
                "shape": "polygon",
                "vertices": [frame.to_world(s, y) for s, y in fill],
                "material": sand(friction_angle),
                "seeding": {"per_cell": 4},
            }
        ],
    }
    return scene, frame


def heap_slopes(s: np.ndarray, y: np.ndarray, h: float) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The slopes (degrees) of the heap's two sides below the orifice, and its surface (bin centres and
    tops, m): a line fitted to the tops of bins of width h between 15% and 85% of the heap's height."""
    below = y < ORIFICE_HEIGHT - 0.01
    s, y = s[below], y[below]
    edges = np.arange(-0.35, 0.35 + h, h)
    top = bin_tops(s, y, edges, empty=-1.0)
    centres = edges + h / 2
    height = top.max()
    slopes = []
    for side in (-1, 1):
        sel = (np.sign(centres) == side) & (top > 0.15 * height) & (top < 0.85 * height)
        if sel.sum() < 2:
            slopes.append(float("nan"))
            continue
        slopes.append(math.degrees(math.atan(abs(np.polyfit(centres[sel], top[sel], 1)[0]))))
    return slopes[0], slopes[1], centres[top > 0], top[top > 0]


def run(quick: bool) -> tuple[list[Record], dict]:
    records: list[Record] = []
    data: dict = {"column": {}, "heap": {}}
    angles = [30.0] if quick else [0.0, 30.0]
    cells = 16 if quick else 24
    aspects = [1.0] if quick else [0.5, 1.0]
    for aspect in aspects:
        for angle in angles:
            scene, frame = column_scene(aspect, cells, angle)
            case = f"granular_column_a{aspect:g}"
            for method in METHODS:
                try:
                    _, sim = simulate(scene, method, [1.2], lambda sim: None)
                except CaseFailed as e:
                    records.append(Record.failed_run(case, method, angle, cells, e))
                    continue
                s, y = frame.coords(sim.positions)
                toe = deposit_toe(s, y, COLUMN_WIDTH / cells)
                coefficient = (toe - COLUMN_WIDTH) / COLUMN_WIDTH / aspect
                lo, hi = RUNOUT_RANGE
                outside_range = max(lo - coefficient, coefficient - hi, 0.0)
                metric = "runout_coefficient_outside_published_range"
                records += [
                    Record(case, method, angle, cells, "runout_coefficient", coefficient, None),
                    Record(case, method, angle, cells, metric, outside_range, 0.0),
                    Record(case, method, angle, cells, "particles_outside_end", sim.metrics()["n_outside"], None),
                ]
                data["column"][(method, aspect, angle)] = surface(s / COLUMN_WIDTH, y / COLUMN_WIDTH, 1.0 / cells)
    # The heap is 0.14 m high: 13 cells at 96, 18 at 128. With φ = 30° its slope came out at 34.1° at 64
    # cells, 30.7° at 96 and 29.3–29.5° at 128: it falls with refinement, and the 2° holds at these two.
    # The quick run does the augmented grid only.
    resolution = 96 if quick else 128
    duration = 6.0
    for angle in angles:
        scene, frame = heap_scene(resolution, angle)
        h = 1.0 / resolution
        for method in ("augmented",) if quick else METHODS:

            def sample(sim, frame=frame, h=h):
                s, y = frame.coords(sim.positions)
                return heap_slopes(s, y, h), int(sim.metrics()["n_outside"])

            times = [duration - 1.0, duration - 0.5, duration]
            try:
                out, sim = simulate(scene, method, times, sample)
            except CaseFailed as e:
                records.append(Record.failed_run("granular_heap", method, angle, resolution, e))
                continue
            slope = float(np.mean([[left, right] for (left, right, _, _), _ in out]))
            outside = max(n for _, n in out)
            records += [
                Record("granular_heap", method, angle, resolution, "heap_angle_deg", slope, None),
                Record("granular_heap", method, angle, resolution, "heap_angle_error_deg", abs(slope - PHI), 2.0),
                Record("granular_heap", method, angle, resolution, "particles_outside_max", outside, None),
            ]
            data["heap"][(method, angle)] = out[-1][0][2:]
    return records, data
