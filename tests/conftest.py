from __future__ import annotations

import copy
from pathlib import Path

import pytest
import tomli_w

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"

_SMALL = {
    "name": "small",
    "seed": 1,
    "gravity": [0.0, -9.81],
    "grid": {"domain": [1.0, 1.0], "resolution": 16},
    "time": {"dt": 1e-3, "steps": 20, "output_interval": 10},
    "walls": [{"type": "polygon", "vertices": [[0.05, 0.3], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]]}],
    "bodies": [
        {
            "shape": "box",
            "min": [0.3, 0.5],
            "max": [0.6, 0.8],
            "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3},
        }
    ],
}


@pytest.fixture
def small_scene() -> dict:
    """A valid scene, small enough to build and step in milliseconds."""
    return copy.deepcopy(_SMALL)


@pytest.fixture
def write_scene(tmp_path):
    def write(data: dict, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(tomli_w.dumps(data), encoding="utf-8")
        return path

    return write


@pytest.fixture(scope="session")
def client():
    """A local Dask cluster of 2 worker processes, one thread each, shared by the sweep and dataset tests."""
    import distributed

    from augmpm.sweep import local_cluster

    cluster = local_cluster(2)
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


def pytest_collection_modifyitems(config, items):
    """The quick validation (test_validation.py, about half of the suite's time on one core) runs first, so that
    the workers of pytest-xdist run the other files beside it rather than after it."""
    items.sort(key=lambda item: item.path.name != "test_validation.py")


def pytest_xdist_auto_num_workers(config):
    """`-n auto` (pyproject.toml): one worker per core this process may use, as `augmpm validate --jobs` counts
    them (pytest-xdist's own count is of physical cores, without the affinity)."""
    from augmpm.simulation import available_cores

    return available_cores()
