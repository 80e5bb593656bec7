"""The Python face of a running simulation."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

import numpy as np

from augmpm import _core
from augmpm.scene import Scene, _plain_error, load_scene

Method = Literal["naive", "augmented"]


class Simulation:
    """A 2D MLS-MPM simulation of a scene.

    >>> sim = Simulation(load_scene("scenes/dam_break.toml"))
    >>> sim.step(100)
    >>> sim.positions.shape  # (N, 2), metres
    """

    def __init__(self, scene: Scene | str | Path, method: Method = "naive", threads: int | None = None) -> None:
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        self.scene = scene
        self.method = method
        self._sim = _core.Simulation(scene.to_json(), method, resolve_threads(threads))

    def step(self, n: int = 1) -> None:
        """Advances ``n`` time steps; raises :class:`augmpm.SimulationError` if the state goes bad."""
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
            raise _core.SceneError(f"n: must be a non-negative integer, got {n!r}")
        self._sim.step(int(n))

    @property
    def positions(self) -> np.ndarray:
        """Particle positions (m), shape (N, 2)."""
        return self._sim.positions

    @property
    def velocities(self) -> np.ndarray:
        """Particle velocities (m/s), shape (N, 2)."""
        return self._sim.velocities

    @property
    def body(self) -> np.ndarray:
        """Body index of each particle, shape (N,)."""
        return self._sim.body

    @property
    def masses(self) -> np.ndarray:
        """Particle masses (kg per metre of depth in 2D), shape (N,)."""
        return self._sim.masses

    @property
    def densities(self) -> np.ndarray:
        """Fluid density of each particle from the regular grid in the last step (kg/m² in 2D), shape (N,)."""
        return self._sim.densities

    @property
    def num_particles(self) -> int:
        return self._sim.num_particles

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self._sim.time

    @property
    def steps_done(self) -> int:
        return self._sim.steps_done

    @property
    def dt(self) -> float:
        """Time step (s)."""
        return self._sim.dt

    @property
    def stable_dt(self) -> float:
        """The materials' stable time step bound (s) on this grid."""
        return self._sim.stable_dt

    @property
    def cell_size(self) -> float:
        """Grid cell width h (m)."""
        return self._sim.cell_size

    @property
    def precision(self) -> str:
        """Floating-point precision of the engine running the scene: "f64" or "f32"."""
        return self._sim.precision

    @property
    def threads(self) -> int:
        """Number of threads the steps run on (results do not depend on it)."""
        return self._sim.threads

    def memory_use(self) -> dict[str, int]:
        """Heap bytes of the particle state, the per-particle scratch of a step and the grid."""
        return self._sim.memory_use()

    def stage_times(self) -> dict[str, float]:
        """Wall-clock seconds spent so far in each stage: sort, density, boundary, p2g, grid, g2p."""
        return self._sim.stage_times()

    @property
    def warnings(self) -> list[str]:
        return self._sim.warnings

    @property
    def boundary_points(self) -> np.ndarray:
        """Boundary grid points (m), shape (B, 2); empty for the naive method."""
        return self._sim.boundary_points

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points (M, 2) to the walls, positive outside the material region."""
        return self._sim.wall_distance(np.ascontiguousarray(points, dtype=np.float64))

    def metrics(self) -> dict[str, float]:
        """``step, time, kinetic_energy, n_outside, max_penetration`` (the last in cell widths)."""
        return self._sim.metrics()


THREADS_ENV = "AUGMPM_THREADS"


def resolve_threads(threads: int | None = None) -> int:
    """The thread count to run on: ``threads`` if given, else ``$AUGMPM_THREADS``, else every core
    this process may use."""
    source = "threads"
    if threads is None and os.environ.get(THREADS_ENV, "").strip():
        source, threads = THREADS_ENV, os.environ[THREADS_ENV].strip()
        try:
            threads = int(threads)
        except ValueError:
            raise _plain_error(THREADS_ENV, f"must be a positive integer, got {threads!r}") from None
    if threads is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if not isinstance(threads, (int, np.integer)) or isinstance(threads, bool) or not 1 <= threads <= 1024:
        raise _plain_error(source, f"must be an integer from 1 to 1024, got {threads!r}")
    return int(threads)
