"""The Python face of a running simulation."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from augmpm import _core
from augmpm.scene import Method, Scene, Scene3, _plain_error, load_scene


class Simulation:
    """A 2D MLS-MPM simulation of a scene.

    >>> sim = Simulation(load_scene("scenes/dam_break.toml"))
    >>> sim.step(100)
    >>> sim.positions.shape  # (N, 2), metres
    """

    def __init__(
        self, scene: Scene | Scene3 | str | Path, method: Method | None = None, threads: int | None = None
    ) -> None:
        if not isinstance(scene, (Scene, Scene3, str, Path)):
            raise _plain_error("scene", f"must be a Scene or the path of a scene file, got {type(scene).__name__}")
        if not isinstance(scene, (Scene, Scene3)):
            scene = load_scene(scene)
        if method is None:
            method = scene.method
        if method not in ("naive", "augmented"):
            raise _plain_error("method", f'must be "naive" or "augmented", got {method!r}')
        if method != scene.method:
            scene = scene.model_copy(update={"method": method})
        self.scene = scene
        self.method = method
        self._sim = _core.Simulation(scene.to_json(), method, resolve_threads(threads), memory_limit())

    def step(self, n: int = 1) -> None:
        """Advances ``n`` time steps; raises :class:`augmpm.SimulationError` if the state goes bad.

        After a failure the state is that of the failing step, and every later call raises the
        same error until a checkpoint is restored (:meth:`restore`).
        """
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or not 0 <= n < 2**63:
            raise _plain_error("n", f"must be an integer from 0 to 2**63 - 1, got {n!r}")
        self._sim.step(int(n))

    def checkpoint(self) -> dict[str, Any]:
        """Everything that evolves during the run, as scalars and numpy arrays: with the same
        scene and method, :meth:`restore` continues from it bitwise identically."""
        return dict(self._sim.checkpoint())

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continues from ``state``, a :meth:`checkpoint` of a simulation of the same scene and method.

        A state that does not fit (missing entries, wrong shapes or types, particles that do not
        match the grid) raises :class:`augmpm.SceneError` naming the entry, and changes nothing.
        """
        if not isinstance(state, Mapping):
            raise _plain_error("state", f"must be a mapping from a checkpoint, got {type(state).__name__}")
        arrays = {}
        for key, value in state.items():
            if key in _STATE_DTYPES:
                try:
                    value = np.ascontiguousarray(value, dtype=_STATE_DTYPES[key])
                except (TypeError, ValueError, OverflowError) as e:
                    raise _plain_error(f"state.{key}", f"not convertible to {_STATE_DTYPES[key]}: {e}") from None
            elif isinstance(value, np.ndarray) and value.ndim == 0:
                value = value.item()
            arrays[str(key)] = value
        self._sim.restore(arrays)

    @property
    def positions(self) -> np.ndarray:
        """Particle positions (m), shape (N, D): D = :attr:`dim`."""
        return self._sim.positions

    @property
    def velocities(self) -> np.ndarray:
        """Particle velocities (m/s), shape (N, D)."""
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
        """Fluid density of each particle in the last step (kg/m² in 2D), shape (N,): ρ0/J with the J its stress
        saw (the one the step before averaged over the grid and advanced) with ``density_estimate =
        "deformation"``, ρ0/J with the J it advanced and relaxed toward the packing with ``"packing"``, gathered
        from the regular grid with ``"grid"``."""
        return self._sim.densities

    def particle_fields(self) -> dict[str, np.ndarray]:
        """Per-particle fields of the current state: ``stress`` (N, D, D), each particle's Cauchy stress
        (N/m in 2D, Pa in 3D); ``J`` (N,), its volume ratio V/V⁰ (fluids ρ0/ρ, solids det F · J_p);
        ``plastic`` (N,), its plastic volume ratio J_p (snow; sand: its loose volume, ≥ 1; 1 for the other
        materials)."""
        return self._sim.particle_fields()

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

    def wall_outlines(self) -> list[tuple[np.ndarray, bool]]:
        """Each scene wall where it is now (a moving wall follows its ``motion``) as the (M, 2) vertices (m)
        of its closed outline (a circle as 64 points), and whether it moves."""
        return self._sim.wall_outlines()

    def wall_points(self, spacing: float) -> np.ndarray:
        """Points on the walls where they are now (the domain box's included), at most ``spacing`` (m)
        apart (at least a quarter cell), shape (P, :attr:`dim`): what a 3D frame draws of the walls."""
        return self._sim.wall_points(_number("spacing", spacing))

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points (M, D) to the walls, positive outside the material region."""
        try:
            points = np.ascontiguousarray(points, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise _plain_error("points", f"must be an (M, {self.dim}) array of numbers: {e}") from None
        if points.ndim != 2 or points.shape[1] != self.dim:
            raise _plain_error("points", f"must have shape (M, {self.dim}), got {points.shape}")
        return self._sim.wall_distance(points)

    def set_wall_pose(
        self,
        wall: int,
        position: Sequence[float],
        angle: float | Sequence[float] = 0.0,
        velocity: Sequence[float] | None = None,
        angular_velocity: float | Sequence[float] = 0.0,
    ) -> None:
        """Puts scene wall ``wall`` (its index in ``walls``) where it is from now on, between steps: its
        pivot (the ``motion``'s ``pivot``, else the wall's centre) displaced by ``position`` (m) from where
        the scene draws it, turned by ``angle`` about it, and moving from now on at ``velocity`` (m/s,
        default at rest) and ``angular_velocity`` until set again; the wall's ``motion``, if any, no longer
        acts. The pose is part of the state (:meth:`checkpoint`).

        In 2D ``angle`` (rad) and ``angular_velocity`` (rad/s) are numbers, counter-clockwise. In 3D they
        are rotation vectors (3 numbers each: about their direction, by their length; ``angle`` is
        applied first, then the turn at ``angular_velocity`` since now); a single number 0 means none. A
        3D plane cannot be posed.

        Raises :class:`augmpm.SceneError` naming the argument: a wall that does not exist or cannot move,
        a non-finite number or a wrong count of them, a pose more than one cell from where the wall is
        now, a velocity that moves it more than a cell in a step, or a simulation that cannot follow
        moving walls.
        """
        if not isinstance(wall, (int, np.integer)) or isinstance(wall, bool) or not 0 <= wall < 2**32:
            raise _plain_error("wall", f"must be a wall index (an integer from 0), got {wall!r}")
        dim = self.dim
        velocity = (0.0,) * dim if velocity is None else velocity
        self._sim.set_wall_pose(
            int(wall),
            _vector("position", position, dim),
            _turn("angle", angle, dim),
            _vector("velocity", velocity, dim),
            _turn("angular_velocity", angular_velocity, dim),
        )

    @property
    def dim(self) -> int:
        """Space dimension: 2, or 3 for a :class:`Scene3`."""
        return self._sim.dim

    @property
    def wall_impulse(self) -> np.ndarray:
        """The impulse (N·s per metre of depth in 2D, N·s in 3D) each scene wall has given the material since
        the start, shape (walls + 1, :attr:`dim`), the domain box last. The force the material puts on a wall
        over an interval is minus the change of its row divided by the interval (``metrics.csv``'s
        ``wall_force_<i>_x``)."""
        return self._sim.wall_impulse

    @property
    def wall_angular_impulse(self) -> np.ndarray:
        """The moment about the origin of each row of :attr:`wall_impulse`, ``Σ x × Δp`` over where it was
        given (N·m·s per metre of depth in 2D, about z, shape (walls + 1,); N·m·s in 3D, shape (walls + 1, 3)).
        The torque on a wall about a point c over an interval is minus the change of its row less
        c × the change of its impulse, over the interval."""
        return self._sim.wall_angular_impulse

    @property
    def rigid_bodies(self) -> np.ndarray:
        """Each of the scene's ``rigid_bodies`` now, one row per body: ``x, y, angle, vx, vy,
        angular_velocity`` (its centre of mass (m), its turn from where the scene draws it (rad,
        counter-clockwise) and their rates (m/s, rad/s)). Its wall is ``len(scene.walls) + k`` in
        :attr:`wall_impulse`."""
        return self._sim.rigid_bodies

    def metrics(self) -> dict[str, float]:
        """``step, time, kinetic_energy, n_outside, max_penetration`` (cell widths), the augmented
        grid's counters ``ill_conditioned, low_mass_nodes, held_at_wall``, and ``max_cfl``: the
        largest distance a particle moved in the last step, in cell widths."""
        return self._sim.metrics()


# Dtypes of the arrays of a checkpoint, from the engine's table of per-particle fields (see
# Simulation.checkpoint); the rest are scalars.
_STATE_DTYPES = {f["name"]: np.dtype(f["dtype"]) for f in _core.state_fields()}
# The walls' part of the state: each wall's impulse so far and its moment, and the poses set by set_wall_pose
# (the rigid bodies' among them); each rigid body's change of velocity over the last step.
_STATE_DTYPES |= {
    "wall_impulse": np.dtype("float64"),
    "wall_angular_impulse": np.dtype("float64"),
    "wall_pose": np.dtype("float64"),
    "body_kick": np.dtype("float64"),
}


def _number(key: str, value: Any) -> float:
    """``value`` as a finite float, or a SceneError naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _plain_error(key, f"must be a number, got {value!r}")
    try:
        number = float(value)
    except OverflowError:
        raise _plain_error(key, f"must be finite, got {value!r}") from None
    if not math.isfinite(number):
        raise _plain_error(key, f"must be finite, got {value!r}")
    return number


def _vector(key: str, value: Any, dim: int) -> list[float]:
    """``value`` as ``dim`` finite floats, or a SceneError naming ``key``."""
    if isinstance(value, np.ndarray):
        value = value.tolist() if value.ndim == 1 else None
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != dim:
        raise _plain_error(key, f"must be {dim} numbers {['[x, y]', '[x, y, z]'][dim - 2]}, got {value!r}")
    return [_number(key, v) for v in value]


def _turn(key: str, value: Any, dim: int) -> list[float]:
    """A turn as the engine takes it: one finite float in 2D; a rotation vector of 3 in 3D (a single 0
    for none). A SceneError names ``key`` otherwise."""
    if dim == 2:
        return [_number(key, value)]
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and value == 0:
        return [0.0, 0.0, 0.0]
    return _vector(key, value, 3)


THREADS_ENV = "AUGMPM_THREADS"
MEMORY_ENV = "AUGMPM_MEMORY_LIMIT"
_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


def memory_limit() -> int:
    """Bytes a simulation may take: ``$AUGMPM_MEMORY_LIMIT`` (e.g. ``512M``, ``8G``, or bytes) if
    set, else the memory the system reports available (MemAvailable on Linux), else all of it."""
    text = os.environ.get(MEMORY_ENV, "").strip()
    if text:
        number, unit = text.rstrip("KMGTkmgtBb"), text[len(text.rstrip("KMGTkmgtBb")) :].upper().rstrip("B")
        try:
            value = float(number) * _UNITS[unit]
        except (KeyError, ValueError):
            value = -1.0
        if not 0 < value < 2**63:
            raise _plain_error(MEMORY_ENV, f"must be a size such as 512M or 8G, got {text!r}")
        return int(value)
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 2**63 - 1


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


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
        return available_cores()
    if not isinstance(threads, (int, np.integer)) or isinstance(threads, bool) or not 1 <= threads <= 1024:
        raise _plain_error(source, f"must be an integer from 1 to 1024, got {threads!r}")
    return int(threads)
