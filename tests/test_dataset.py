"""Training sets for learned simulators (`augmpm dataset`): the GNS format (keys, shapes, dtypes,
metadata and its statistics), determinism per seed, resuming, leak figures, and bad specs."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import augmpm
from augmpm.cli import main
from augmpm.dataset import (
    MATERIALS,
    PARTICLE_TYPES,
    WALL_TYPE,
    DatasetSpec,
    load_spec,
    make_dataset,
    trajectory_scene,
)

#: Four short trajectories on a coarse grid: seconds in all.
SMALL = """
seed = 5
trajectories = { train = 2, valid = 1, test = 1 }
resolution = 24
steps = 60
frame_interval = 10
"""


def _spec(tmp_path: Path, text: str, name: str = "dataset.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _load(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    with np.load(path, allow_pickle=True) as z:
        return {k: tuple(z[k]) for k in z.files}


def test_set_has_the_gns_format_and_its_statistics(tmp_path, client):
    """The splits map simulation_trajectory_<i> to (positions [T, N, 2] float32, types [N] int64), the
    walls as type-3 particles that do not move, inside the metadata's bounds; metadata.json has the GNS
    keys, with velocity and acceleration statistics equal to those of the training positions' differences."""
    result = make_dataset(_spec(tmp_path, SMALL), tmp_path / "set", progress=False, client=client)
    out = tmp_path / "set"
    meta = json.loads((out / "metadata.json").read_text(encoding="utf-8"))
    for key in ("bounds", "sequence_length", "default_connectivity_radius", "dim", "dt"):
        assert key in meta
    assert meta["sequence_length"] == 7 and meta["dim"] == 2 and meta["bounds"] == [[0.0, 1.0], [0.0, 1.0]]
    assert math.isclose(meta["dt"], meta["simulation_dt"] * 10)
    assert meta["default_connectivity_radius"] == pytest.approx(1.5 / 24)
    velocities, accelerations = [], []
    for split, count in (("train", 2), ("valid", 1), ("test", 1)):
        trajectories = _load(out / f"{split}.npz")
        assert sorted(trajectories) == [f"simulation_trajectory_{i}" for i in range(count)]
        for positions, types in trajectories.values():
            assert positions.dtype == np.float32 and types.dtype == np.int64
            assert positions.ndim == 3 and positions.shape[0] == 7 and positions.shape[2] == 2
            assert types.shape == (positions.shape[1],)
            assert set(types) <= set(PARTICLE_TYPES.values()) and WALL_TYPE in set(types)
            assert np.all((positions >= 0.0) & (positions <= 1.0))
            walls = positions[:, types == WALL_TYPE]
            assert np.array_equal(walls, np.broadcast_to(walls[0], walls.shape))
            material = positions[:, types != WALL_TYPE].astype(np.float64)
            assert np.any(material[-1] != material[0])  # the material moved
            if split == "train":
                v = np.diff(material, axis=0)
                velocities.append(v.reshape(-1, 2))
                accelerations.append(np.diff(v, axis=0).reshape(-1, 2))
    v, a = np.concatenate(velocities), np.concatenate(accelerations)
    np.testing.assert_allclose(meta["vel_mean"], v.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(meta["vel_std"], v.std(axis=0), rtol=1e-12)
    np.testing.assert_allclose(meta["acc_mean"], a.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(meta["acc_std"], a.std(axis=0), rtol=1e-12)
    # Every trajectory's leak figures; the augmented grid's set is leak-free, and says so.
    with open(out / "trajectories.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["split"], r["index"]) for r in rows] == [("train", "0"), ("train", "1"), ("valid", "0"), ("test", "0")]
    assert all(r["method"] == "augmented" and r["max_n_outside"] == "0" for r in rows)
    assert meta["leak_free"] is True and all(r["leak_free"] for r in result.rows)


def test_same_seed_same_set_and_resumed_sets_redo_nothing(tmp_path, client):
    """The same spec gives the same files byte for byte, in another directory; run again in the same one it
    generates nothing; another seed gives other scenes."""
    spec = _spec(tmp_path, SMALL)
    make_dataset(spec, tmp_path / "a", progress=False, client=client)
    make_dataset(spec, tmp_path / "b", progress=False, client=client)
    for name in ("train.npz", "valid.npz", "test.npz", "metadata.json", "trajectories.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    stamps = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "a" / "parts").iterdir()}
    make_dataset(spec, tmp_path / "a", progress=False, client=client)
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "a" / "parts").iterdir()} == stamps
    other = load_spec(_spec(tmp_path, SMALL.replace("seed = 5", "seed = 6"), "other.toml"))
    assert trajectory_scene(other, "train", 0) != trajectory_scene(load_spec(spec), "train", 0)


@pytest.mark.parametrize(("resolution", "max_angle"), [(16, 45.0), (20, 45.0), (24, 30.0)])
def test_coarse_or_turned_scenes_are_valid(tmp_path, resolution, max_angle):
    """At the coarsest resolutions and the largest turns a spec allows, every random scene builds: its bodies
    are clear of the walls, the engine takes it."""
    spec = load_spec(_spec(tmp_path, f"resolution = {resolution}\nmax_angle = {max_angle}\n"))
    for i in range(30):
        data = trajectory_scene(spec, "train", i, dt=1e-4)
        for b in data["bodies"]:
            b.pop("name_")
        augmpm.Simulation(augmpm.Scene.from_dict(data), threads=1)


def test_random_scenes_hold_every_material_and_stay_valid(tmp_path):
    """Over many seeds the scenes draw every material, turn their containers both ways within max_angle,
    place obstacles, and are all valid scenes (bodies clear of the walls: the engine builds them)."""
    spec = load_spec(_spec(tmp_path, "max_angle = 20.0\n"))
    kinds, angles, obstacles = set(), [], 0
    for i in range(40):
        data = trajectory_scene(spec, "train", i, dt=1e-4)
        kinds |= {b["name_"] for b in data["bodies"]}
        (x0, y0), (x1, y1) = data["walls"][0]["vertices"][:2]
        angles.append(math.degrees(math.atan2(y1 - y0, x1 - x0)))
        obstacles += len(data["walls"]) - 1
        for b in data["bodies"]:
            b.pop("name_")
        augmpm.Simulation(augmpm.Scene.from_dict(data), threads=1)
    assert kinds == set(MATERIALS)
    assert max(angles) > 5 and min(angles) < -5 and all(abs(a) <= 20.0 + 1e-9 for a in angles)
    assert obstacles > 10


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("trajectories = { train = 0 }", "trajectories"),
        ("trajectories = { train = 1, tests = 1 }", "trajectories"),
        ('materials = ["water", "lava"]', "materials"),
        ("resolution = 4", "resolution"),
        ("steps = 100\nframe_interval = 30", "frame_interval"),
        ("bodies = [3, 1]", "bodies"),
        ('method = "exact"', "method"),
        ("max_angle = 60.0", "max_angle"),
        ("colour = 1", "colour"),
    ],
)
def test_a_bad_spec_names_its_key(tmp_path, text, key, capsys):
    """A bad spec is refused by `augmpm dataset` with exit code 2, naming the key; nothing is generated."""
    assert main(["dataset", str(_spec(tmp_path, text)), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert f"{key}:" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_the_shipped_example_spec_gives_the_defaults():
    """datasets/mixed_materials.toml, which the README shows, writes out every default and nothing else."""
    path = Path(__file__).resolve().parents[1] / "datasets" / "mixed_materials.toml"
    assert load_spec(path) == DatasetSpec()
