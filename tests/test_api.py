"""The Python API: building scenes in code, stepping, reading particle arrays."""

from __future__ import annotations

import numpy as np
import pytest

import augmpm


def test_simulation_arrays_and_clock(small_scene):
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene), method="naive")
    n = sim.num_particles
    assert sim.positions.shape == (n, 2) and sim.positions.dtype == np.float64
    assert sim.velocities.shape == (n, 2)
    assert sim.body.shape == (n,)
    sim.step(5)
    assert sim.steps_done == 5
    assert sim.time == pytest.approx(5 * sim.dt, rel=1e-14)


def test_scene_in_code_free_falls():
    """A body far from the walls falls freely: after n steps its mean velocity is −g·n·dt."""
    scene = augmpm.Scene(
        gravity=(0.0, -9.81),
        grid={"domain": (1.0, 1.0), "resolution": 32},
        time={"dt": 1e-3, "steps": 50, "output_interval": 10},
        bodies=[
            {
                "shape": "circle",
                "center": (0.5, 0.7),
                "radius": 0.1,
                "material": {"type": "stvk", "density": 500.0, "youngs_modulus": 1e5, "poisson_ratio": 0.2},
            }
        ],
    )
    sim = augmpm.Simulation(scene)
    sim.step(50)
    v = sim.velocities
    assert np.allclose(v[:, 1], -9.81 * 50 * 1e-3, rtol=1e-10)
    assert np.allclose(v[:, 0], 0.0, atol=1e-12)


def test_same_seed_same_particles_other_seed_differs(small_scene):
    a = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    b = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    assert np.array_equal(a.positions, b.positions)
    small_scene["seed"] = 2
    c = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    assert not np.array_equal(a.positions, c.positions)


def test_wall_distance_is_signed(small_scene):
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    d = sim.wall_distance(np.array([[0.5, 0.5], [0.5, 0.0]]))
    assert d[0] < 0 < d[1]
    with pytest.raises(ValueError):
        sim.wall_distance(np.zeros((2, 3)))


def test_errors_share_one_family(small_scene):
    assert issubclass(augmpm.SceneError, augmpm.Error)
    assert issubclass(augmpm.SimulationError, augmpm.Error)
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    with pytest.raises(augmpm.SceneError):
        sim.step(-1)
    with pytest.raises(augmpm.SceneError):
        augmpm.Simulation(augmpm.Scene.from_dict(small_scene), method="magic")


def test_blow_up_raises_simulation_error(small_scene):
    small_scene["time"]["dt"] = 0.2
    small_scene["bodies"][0]["material"]["youngs_modulus"] = 1e9
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene))
    with pytest.raises(augmpm.SimulationError) as err:
        sim.step(200)
    assert err.value.step <= 200
    assert "particle" in str(err.value)
