"""Shared pieces of the validation cases: rotated frames, fluids, running a scene and sampling it."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from augmpm._core import SimulationError
from augmpm.scene import scene_class
from augmpm.simulation import Simulation
from augmpm.validation import bounds

METHODS = ("naive", "augmented")


@dataclass(frozen=True)
class Frame:
    """An orthonormal frame rotated by `angle_deg` to the grid: `t` along, `n` across (m)."""

    origin: tuple[float, float]
    angle_deg: float

    @property
    def t(self) -> np.ndarray:
        a = math.radians(self.angle_deg)
        return np.array([math.cos(a), math.sin(a)])

    @property
    def n(self) -> np.ndarray:
        a = math.radians(self.angle_deg)
        return np.array([-math.sin(a), math.cos(a)])

    def to_world(self, s: float, y: float) -> list[float]:
        p = np.asarray(self.origin) + s * self.t + y * self.n
        return [float(p[0]), float(p[1])]

    def rect(self, s0: float, s1: float, y0: float, y1: float) -> list[list[float]]:
        """Counter-clockwise corners of the rectangle [s0, s1] × [y0, y1] in this frame."""
        return [self.to_world(s0, y0), self.to_world(s1, y0), self.to_world(s1, y1), self.to_world(s0, y1)]

    def coords(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = x - np.asarray(self.origin)
        return d @ self.t, d @ self.n


def fluid(density: float, sound_speed: float, viscosity: float, gamma: float = 7.0, tension: float = 0.0) -> dict:
    """A weakly compressible fluid with the given sound speed c (m/s): k = ρ c² / γ.

    `tension` lets the pressure fall to −tension·k: a little tension keeps a sheared fluid from
    dilating (with p ≥ 0 nothing pulls a gap shut), and too much of it pulls particles apart.
    """
    stiffness = density * sound_speed**2 / gamma
    return {
        "type": "fluid",
        "density": density,
        "stiffness": stiffness,
        "gamma": gamma,
        "viscosity": viscosity,
        "min_pressure": -tension * stiffness,
    }


class CaseFailed(Exception):
    """A case's simulation failed (non-finite state, a particle leaving the grid) at `time` (s)."""

    def __init__(self, message: str, time: float) -> None:
        super().__init__(message, time)
        self.time = time

    def __str__(self) -> str:
        return str(self.args[0])


def simulate(
    scene: dict,
    method: str,
    sample_times: list[float],
    sample: Callable[[Simulation], object],
) -> tuple[list[object], Simulation]:
    """Runs `scene` (2D or 3D) with `method` and calls `sample(sim)` at each of `sample_times` (s, increasing);
    the fluids' J inside the water is watched there too (:mod:`augmpm.validation.bounds`). Raises `CaseFailed`
    when the simulation fails."""
    sim = Simulation(scene_class(scene).from_dict(scene), method)
    out = []
    for t in sample_times:
        n = max(0, round((t - sim.time) / sim.dt))
        try:
            sim.step(n)
        except SimulationError as e:
            raise CaseFailed(str(e), sim.time) from None
        out.append(sample(sim))
        bounds.watch(sim, method)
    return out, sim


#: The observed order a second-order interpolation must reach. Measured between two finite resolutions, a
#: second-order method reads below 2 (1.85–1.91 for the augmented grid's circle and sphere), so 1.8.
SECOND_ORDER = 1.8


def observed_order(h: list[float], err: list[float]) -> float:
    """Least-squares slope of log(error) against log(h)."""
    lh, le = np.log(np.asarray(h)), np.log(np.maximum(np.asarray(err), 1e-300))
    return float(np.polyfit(lh, le, 1)[0])
