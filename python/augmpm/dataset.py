"""Training sets for learned simulators (the GNS family), generated on Dask: ``augmpm dataset SPEC``.

Each trajectory is a random 2D scene in the unit box: a square container turned by a random angle,
round and polygonal obstacles at random angles inside it, and bodies of water, goop (a viscous fluid),
elastic material, snow and sand at random places with random velocities. It is simulated with the spec's wall
method and written as the GNS family reads its data (Sanchez-Gonzalez et al. 2020; the `gns` package):

- ``train.npz``, ``valid.npz``, ``test.npz``: ``simulation_trajectory_<i>`` → an object array
  ``(positions [T, N, 2] float32 (m), particle_type [N] int64)``; the walls are sampled as particles of
  their own type (:data:`WALL_TYPE`, as kinematic particles are in the GNS sets), after the material's,
  at the same place in every frame;
- ``metadata.json``: ``bounds``, ``sequence_length`` (T), ``default_connectivity_radius`` (m), ``dim``,
  ``dt`` (s between frames), ``vel_mean``, ``vel_std``, ``acc_mean``, ``acc_std`` (per axis, over the
  material particles of the training set: velocities as position differences of consecutive frames, m
  per frame, accelerations as their differences, m per frame²), and what the set was made with;
- ``trajectories.csv``: each trajectory's scene, particle counts and leak figures (the most particles
  outside the walls in any frame, the deepest one past a wall, cells h): a set made with the augmented
  grid says, trajectory by trajectory, that no particle left.

The same SPEC and seed give the same set, bitwise. A trajectory already generated (``parts/``) is not
generated again: the same command resumes an interrupted set.
"""

from __future__ import annotations

import csv
import io
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from augmpm import _core
from augmpm.files import npz_bytes, output_dir, write_bytes, write_npz, write_text
from augmpm.scene import Scene, _plain_error

#: Particle types: the GNS sets' numbers (3 kinematic, 5 water, 6 sand, 7 goop), then ours in the ids they
#: leave free below 9 (the `gns` package embeds 9 types, 0 to 8).
PARTICLE_TYPES = {"wall": 3, "water": 5, "goop": 7, "elastic": 8, "snow": 4, "sand": 6}
WALL_TYPE = PARTICLE_TYPES["wall"]
#: The materials a set may hold, as scene materials (2D: per unit area, N/m stresses).
MATERIALS: dict[str, dict[str, Any]] = {
    "water": {"type": "fluid", "density": 1000.0, "stiffness": 2.0e4, "gamma": 7.0, "viscosity": 0.5},
    "goop": {"type": "fluid", "density": 1000.0, "stiffness": 2.0e4, "gamma": 7.0, "viscosity": 20.0},
    "elastic": {"type": "elastic", "density": 1000.0, "youngs_modulus": 4.0e4, "poisson_ratio": 0.3},
    "snow": {"type": "snow", "density": 400.0, "youngs_modulus": 4.0e4, "poisson_ratio": 0.2},
    "sand": {"type": "sand", "density": 2200.0, "youngs_modulus": 2.0e5, "poisson_ratio": 0.3, "friction_angle": 30.0},
}
SPLITS = ("train", "valid", "test")
_SPEC_KEYS = {
    "seed",
    "trajectories",
    "method",
    "resolution",
    "steps",
    "frame_interval",
    "materials",
    "bodies",
    "obstacles",
    "max_angle",
    "max_speed",
    "connectivity_radius",
}


@dataclass
class DatasetSpec:
    """A training set, read from SPEC by :func:`load_spec` (defaults: a small set, a minute on 2 cores)."""

    seed: int = 0
    trajectories: dict[str, int] = field(default_factory=lambda: {"train": 8, "valid": 2, "test": 2})
    method: str = "augmented"
    resolution: int = 48
    steps: int = 1200
    frame_interval: int = 10
    materials: list[str] = field(default_factory=lambda: list(MATERIALS))
    bodies: tuple[int, int] = (1, 3)
    obstacles: tuple[int, int] = (0, 2)
    max_angle: float = 30.0
    max_speed: float = 1.0
    connectivity_radius: float | None = None

    @property
    def h(self) -> float:
        return 1.0 / self.resolution

    @property
    def radius(self) -> float:
        """The default connectivity radius (m): 1.5 cells, about 25 neighbours at 4 particles a cell."""
        return self.connectivity_radius if self.connectivity_radius is not None else 1.5 * self.h

    def tasks(self) -> list[tuple[str, int]]:
        return [(split, i) for split in SPLITS for i in range(self.trajectories.get(split, 0))]


def load_spec(path: str | Path) -> DatasetSpec:
    """Reads and checks a dataset SPEC; bad input raises :class:`augmpm.SceneError` naming the key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise _plain_error(str(path), f"cannot read dataset spec ({e.strerror})") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise _plain_error(str(path), f"not a valid TOML file: {e}") from None
    unknown = sorted(set(data) - _SPEC_KEYS)
    if unknown:
        raise _plain_error(unknown[0], f"not a dataset key (expected one of {', '.join(sorted(_SPEC_KEYS))})")
    spec = DatasetSpec()

    def integer(key: str, low: int, high: int | None = None) -> None:
        if key in data:
            v = data[key]
            if not isinstance(v, int) or isinstance(v, bool) or v < low or (high is not None and v > high):
                within = f"in [{low}, {high}]" if high is not None else f"≥ {low}"
                raise _plain_error(key, f"must be an integer {within}, got {v!r}")
            setattr(spec, key, v)

    def number(key: str, low: float, high: float) -> None:
        if key in data:
            v = data[key]
            if not isinstance(v, int | float) or isinstance(v, bool) or not low <= v <= high:
                raise _plain_error(key, f"must be a number in [{low:g}, {high:g}], got {v!r}")
            setattr(spec, key, float(v))

    def count_range(key: str, low: int) -> None:
        if key in data:
            v = data[key]
            ok = isinstance(v, list) and len(v) == 2 and all(isinstance(a, int) and not isinstance(a, bool) for a in v)
            if not ok or v[0] < low or v[0] > v[1] or v[1] > 8:
                raise _plain_error(key, f"must be [least, most] with {low} ≤ least ≤ most ≤ 8, got {v!r}")
            setattr(spec, key, (v[0], v[1]))

    integer("seed", 0)
    integer("resolution", 16, 1024)
    integer("steps", 1)
    integer("frame_interval", 1)
    number("max_angle", 0.0, 45.0)
    number("max_speed", 0.0, 10.0)
    count_range("bodies", 1)
    count_range("obstacles", 0)
    if "connectivity_radius" in data:
        number("connectivity_radius", 1e-9, 1.0)
    if "method" in data:
        if data["method"] not in ("naive", "augmented"):
            raise _plain_error("method", f"must be naive or augmented, got {data['method']!r}")
        spec.method = data["method"]
    if "materials" in data:
        m = data["materials"]
        if not isinstance(m, list) or not m or any(x not in MATERIALS for x in m):
            raise _plain_error("materials", f"must be a non-empty list of {', '.join(MATERIALS)}, got {m!r}")
        spec.materials = list(dict.fromkeys(m))
    if "trajectories" in data:
        t = data["trajectories"]
        ok = isinstance(t, dict) and set(t) <= set(SPLITS)
        ok = ok and all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in t.values())
        if not ok or not t.get("train"):
            raise _plain_error("trajectories", f"must be {{ train = n ≥ 1, valid = n, test = n }}, got {t!r}")
        spec.trajectories = {s: t.get(s, 0) for s in SPLITS}
    if spec.steps % spec.frame_interval:
        raise _plain_error("frame_interval", f"must divide steps ({spec.steps}), got {spec.frame_interval}")
    if spec.steps // spec.frame_interval < 2:
        raise _plain_error("frame_interval", "leaves fewer than 3 frames: accelerations need 3")
    return spec


def _rotated(points: np.ndarray, angle: float, centre: np.ndarray) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return (points - centre) @ np.array([[c, s], [-s, c]]) + centre


def trajectory_scene(spec: DatasetSpec, split: str, index: int, dt: float | None = None) -> dict[str, Any]:
    """The random scene of one trajectory: a function of the spec's seed, the split and the index only."""
    rng = np.random.default_rng([spec.seed, SPLITS.index(split), index])
    h = spec.h
    margin = 2.0 * h
    centre = np.array([0.5, 0.5])
    angle = math.radians(rng.uniform(-spec.max_angle, spec.max_angle))
    # The largest square turned by `angle` that stays `margin` inside the unit box.
    side = (1.0 - 2.0 * margin) / (abs(math.cos(angle)) + abs(math.sin(angle)))
    half = side / 2.0
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) + centre
    walls: list[dict[str, Any]] = [{"type": "polygon", "vertices": _rotated(square, -angle, centre).tolist()}]
    # Disks kept clear of one another and of the container's sides: (centre, radius) in the square's frame.
    taken: list[tuple[np.ndarray, float]] = []

    def place(radius: float, low: float, high: float) -> np.ndarray | None:
        """A free place for a disk of ``radius`` inside the container, its centre's height in [low, high]
        (the container's frame), or None (no draw is taken from an empty range)."""
        low, high = max(low, -half + radius + margin), min(high, half - radius - margin)
        if low > high or half - radius - margin < 0:
            return None
        for _ in range(100):
            p = np.array([rng.uniform(-half + radius + margin, half - radius - margin), rng.uniform(low, high)])
            if all(np.linalg.norm(p - q) > radius + r + margin for q, r in taken):
                taken.append((p, radius))
                return p
        return None

    # The bodies first, so that obstacles take only the room they leave.
    bodies = []
    for _ in range(int(rng.integers(spec.bodies[0], spec.bodies[1] + 1))):
        kind = spec.materials[int(rng.integers(len(spec.materials)))]
        radius = rng.uniform(0.06, 0.12)
        p = place(radius, -half / 2, half - radius - margin)
        if p is None:
            continue
        where = _rotated(p[None] + centre, -angle, centre)[0]
        speed, heading = rng.uniform(0, spec.max_speed), rng.uniform(0, 2 * math.pi)
        body: dict[str, Any] = {
            "material": dict(MATERIALS[kind]),
            "velocity": [speed * math.cos(heading), speed * math.sin(heading)],
        }
        if rng.uniform() < 0.5:
            body |= {"shape": "circle", "center": where.tolist(), "radius": float(radius)}
        else:
            r = radius / math.sqrt(2.0)
            body |= {"shape": "box", "min": (where - r).tolist(), "max": (where + r).tolist()}
        body["name_"] = kind
        bodies.append(body)
    radius = 0.06
    while not bodies and radius >= h:  # every place was taken: smaller bodies, anywhere free
        p = place(radius, -half, half)
        if p is not None:
            where = _rotated(p[None] + centre, -angle, centre)[0]
            bodies.append({"material": dict(MATERIALS[spec.materials[0]]), "shape": "circle"})
            bodies[-1] |= {"center": where.tolist(), "radius": radius, "name_": spec.materials[0]}
        radius *= 0.8
    if not bodies:
        raise _plain_error("resolution", f"{spec.resolution} cells leave no room for a body between the walls")
    for _ in range(int(rng.integers(spec.obstacles[0], spec.obstacles[1] + 1))):
        radius = rng.uniform(0.04, 0.08)
        p = place(radius, -half + radius + 4 * h, 0.0)
        if p is None:
            continue
        where = (_rotated(p[None] + centre, -angle, centre))[0]
        if rng.uniform() < 0.5:
            walls.append({"type": "circle", "center": where.tolist(), "radius": float(radius)})
        else:
            k = int(rng.integers(3, 6))
            turn = rng.uniform(0, 2 * math.pi)
            corners = [[math.cos(turn + 2 * math.pi * j / k), math.sin(turn + 2 * math.pi * j / k)] for j in range(k)]
            vertices = (np.array(corners) * radius + where).tolist()
            walls.append({"type": "polygon", "vertices": vertices, "side": "outside"})
    time: dict[str, Any] = {"steps": spec.steps, "output_interval": spec.frame_interval}
    time |= {"dt": dt} if dt is not None else {"cfl": 0.25}
    return {
        "name": f"{split}_{index:05d}",
        "seed": int(rng.integers(2**31)),
        "gravity": [0.0, -9.81],
        "wall_condition": "slip",
        "method": spec.method,
        "grid": {"domain": [1.0, 1.0], "resolution": spec.resolution},
        "time": time,
        "walls": walls,
        "bodies": bodies,
    }


def _scene(data: dict[str, Any]) -> tuple[Scene, list[str]]:
    """The scene of ``data`` and its bodies' material names."""
    data = json.loads(json.dumps(data))
    kinds = [b.pop("name_") for b in data["bodies"]]
    return Scene.from_dict(data), kinds


def time_step(spec: DatasetSpec) -> float:
    """One dt for the whole set (its metadata has one): a quarter of the stable step of its stiffest
    material at the spec's resolution."""
    from augmpm.simulation import Simulation

    dts = []
    for kind in spec.materials:
        data = trajectory_scene(spec, "train", 0)
        data["walls"] = data["walls"][:1]
        data["bodies"] = [{"material": dict(MATERIALS[kind]), "shape": "circle", "center": [0.5, 0.5]}]
        data["bodies"][0] |= {"radius": 0.05, "name_": kind}
        dts.append(Simulation(_scene(data)[0], spec.method, threads=1).dt)
    return min(dts)


def generate_trajectory(spec: DatasetSpec, split: str, index: int, dt: float, path: str, threads: int | None) -> dict:
    """Simulates one trajectory and writes it to ``path`` (``.npz``: positions, particle_type, the leak
    figures and the scene); returns its row of ``trajectories.csv``. On a worker."""
    from augmpm.simulation import Simulation

    data = trajectory_scene(spec, split, index, dt)
    scene, kinds = _scene(data)
    sim = Simulation(scene, spec.method, threads=threads)
    walls = sim.wall_points(0.5 * spec.h)
    types = np.concatenate(
        [np.array([PARTICLE_TYPES[kinds[b]] for b in sim.body], np.int64), np.full(len(walls), WALL_TYPE, np.int64)]
    )
    frames = spec.steps // spec.frame_interval + 1
    positions = np.empty((frames, len(types), 2), np.float32)
    positions[:, sim.num_particles :] = walls.astype(np.float32)
    outside, deepest, error = 0, 0.0, ""
    for t in range(frames):
        if t:
            try:
                sim.step(spec.frame_interval)
            except _core.SimulationError as e:  # a trajectory that went bad is reported, not written half
                error = str(e)
                break
        positions[t, : sim.num_particles] = sim.positions.astype(np.float32)
        m = sim.metrics()
        outside, deepest = max(outside, int(m["n_outside"])), max(deepest, float(m["max_penetration"]))
    row = {
        "split": split,
        "index": index,
        "method": spec.method,
        "particles": sim.num_particles,
        "wall_points": len(walls),
        "materials": " ".join(sorted(set(kinds))),
        "obstacles": len(data["walls"]) - 1,
        "max_n_outside": outside,
        "max_penetration": deepest,
        "leak_free": outside == 0,
        "error": error,
    }
    if not error:
        arrays = {"positions": positions, "particle_type": types, "scene": np.array(scene.to_json())}
        write_npz(path, arrays)
    return row


@dataclass
class DatasetResult:
    out: Path
    rows: list[dict[str, Any]]
    metadata: dict[str, Any]


def make_dataset(
    spec: DatasetSpec | str | Path,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    client: Any = None,
) -> DatasetResult:
    """Generates the set of ``spec`` into ``out`` on Dask (see :func:`augmpm.sweep.dask_client`)."""
    from augmpm.sweep import _bar, dask_client

    if not isinstance(spec, DatasetSpec):
        spec = load_spec(spec)
    out = output_dir(out)
    parts = out / "parts"
    parts.mkdir(exist_ok=True)
    record = {k: (list(v) if isinstance(v, tuple) else v) for k, v in spec.__dict__.items()}
    if (out / "spec.json").exists() and json.loads((out / "spec.json").read_text(encoding="utf-8")) != record:
        raise _plain_error("--out", f"{out} holds another set (its spec.json differs): give another --out")
    write_text(out / "spec.json", json.dumps(record, indent=1))
    dt = time_step(spec)
    tasks = spec.tasks()
    rows: dict[tuple[str, int], dict[str, Any]] = {}
    part = {task: parts / f"{task[0]}_{task[1]:05d}.npz" for task in tasks}
    done_rows = _read_rows(out / "trajectories.csv")
    todo = [t for t in tasks if not (part[t].exists() and t in done_rows)]
    rows.update({t: done_rows[t] for t in tasks if t not in todo})
    if todo:
        from distributed import as_completed

        with dask_client(scheduler, workers, client) as (client, threads):
            futures = {
                client.submit(generate_trajectory, spec, s, i, dt, str(part[(s, i)]), threads, pure=False): (s, i)
                for s, i in todo
            }
            bar = _bar(len(todo), progress, label="dataset", unit="trajectory")
            for future in as_completed(futures):
                split, index = futures[future]
                try:
                    rows[(split, index)] = future.result()
                except Exception as e:  # a worker lost too often, or an error outside the simulation
                    rows[(split, index)] = {
                        **dict.fromkeys(_COLUMNS, ""),
                        **{"split": split, "index": index, "method": spec.method},
                        "error": f"{type(e).__name__}: {e}",
                    }
                bar.update(1)
                _write_rows(out / "trajectories.csv", [rows[t] for t in tasks if t in rows])
            bar.close()
    ordered = [rows[t] for t in tasks]
    _write_rows(out / "trajectories.csv", ordered)
    failed = [r for r in ordered if r["error"]]
    if failed:
        first = failed[0]
        raise _core.SimulationError(
            f"trajectory {first['split']} {first['index']} failed ({len(failed)} in all; a trajectory is the same "
            f"every time, so change the spec, e.g. its seed or max_speed, to go on): {first['error']}"
        )
    metadata = _assemble(spec, out, tasks, part, dt, ordered)
    return DatasetResult(out=out, rows=ordered, metadata=metadata)


def _assemble(spec: DatasetSpec, out: Path, tasks, part, dt: float, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Writes ``train.npz``, ``valid.npz``, ``test.npz`` and ``metadata.json`` from the parts."""
    velocities, accelerations = [], []
    for split in SPLITS:
        entries = {}
        for s, i in tasks:
            if s != split:
                continue
            with np.load(part[(s, i)]) as z:
                positions, types = z["positions"], z["particle_type"]
            pair = np.empty(2, dtype=object)
            pair[0], pair[1] = positions, types
            entries[f"simulation_trajectory_{i}"] = pair
            if split == "train":
                material = positions[:, types != WALL_TYPE].astype(np.float64)
                v = np.diff(material, axis=0)
                velocities.append(v.reshape(-1, 2))
                accelerations.append(np.diff(v, axis=0).reshape(-1, 2))
        write_bytes(out / f"{split}.npz", npz_bytes(entries, compress=True, allow_pickle=True))
    v, a = np.concatenate(velocities), np.concatenate(accelerations)
    metadata = {
        "bounds": [[0.0, 1.0], [0.0, 1.0]],
        "sequence_length": spec.steps // spec.frame_interval + 1,
        "default_connectivity_radius": spec.radius,
        "dim": 2,
        "dt": dt * spec.frame_interval,
        "vel_mean": v.mean(axis=0).tolist(),
        "vel_std": v.std(axis=0).tolist(),
        "acc_mean": a.mean(axis=0).tolist(),
        "acc_std": a.std(axis=0).tolist(),
        "particle_types": PARTICLE_TYPES,
        "method": spec.method,
        "simulation_dt": dt,
        "frame_interval": spec.frame_interval,
        "seed": spec.seed,
        "trajectories": {s: spec.trajectories.get(s, 0) for s in SPLITS},
        "leak_free": all(r["leak_free"] for r in rows),
        "max_n_outside": max(r["max_n_outside"] for r in rows),
        "max_penetration": max(r["max_penetration"] for r in rows),
    }
    write_text(out / "metadata.json", json.dumps(metadata, indent=1))
    return metadata


_COLUMNS = [
    "split",
    "index",
    "method",
    "particles",
    "wall_points",
    "materials",
    "obstacles",
    "max_n_outside",
    "max_penetration",
    "leak_free",
    "error",
]


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_text(path, text.getvalue())


def _read_rows(path: Path) -> dict[tuple[str, int], dict[str, Any]]:
    if not path.exists():
        return {}
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    typed = {}
    for r in rows:
        if r.get("error"):
            continue  # a failed trajectory is tried again
        row = {
            **r,
            "index": int(r["index"]),
            "particles": int(r["particles"]),
            "wall_points": int(r["wall_points"]),
            "obstacles": int(r["obstacles"]),
            "max_n_outside": int(r["max_n_outside"]),
            "max_penetration": float(r["max_penetration"]),
            "leak_free": r["leak_free"] == "True",
        }
        typed[(row["split"], row["index"])] = row
    return typed


def format_summary(result: DatasetResult) -> str:
    m = result.metadata
    leaks = sum(not r["leak_free"] for r in result.rows)
    splits = ", ".join(f"{n} {s}" for s, n in m["trajectories"].items())
    if leaks:
        verdict = f"{leaks} trajectories leaked (at most {m['max_n_outside']} particles outside, "
        verdict += f"{m['max_penetration']:.3g} h deep)"
    else:
        verdict = "no particle left the walls in any trajectory"
    return (
        f"{len(result.rows)} trajectories in {result.out} ({splits}), {m['sequence_length']} frames each, "
        f"{m['dt']:.3g} s apart; method {m['method']}: {verdict}\n"
        "written: train.npz, valid.npz, test.npz, metadata.json, trajectories.csv"
    )
