"""Rigid bodies that the material pushes and that push it back (``rigid_bodies``): a body is a wall the
engine poses from gravity and the impulse its wall conditions give the material."""

from __future__ import annotations

import math
import re
import shutil

import numpy as np
import pytest
import tomli_w

import augmpm
from augmpm.run import BODY_COLUMNS, BODY_COLUMNS_3D, resume_run, run_scene
from augmpm.validation import rigid

G = 9.81
WATER = rigid.WATER
BOX = [[0.4, 0.40], [0.6, 0.40], [0.6, 0.5], [0.4, 0.5]]
_scene = rigid.tank


def test_a_box_half_as_dense_as_water_floats():
    """A box of density ρ/2 dropped onto water in a tank whose floor is at an angle to the grid floats: it
    comes nearly to rest across the surface (0.15 cell of motion over the last 0.5 s of 3 s measured;
    asserted < 0.25), and no water enters it at any sampled step (augmented, 48 cells). Its submerged part
    is 0.58 of it where Archimedes says 0.5, measured against the surface taken from the highest particles
    (the issue's 2% is not claimed: see the README); asserted between 0.4 and 0.7."""
    body = {"shape": "polygon", "vertices": BOX, "density": 500.0}
    sim = augmpm.Simulation(_scene([body], end=3.0), "augmented")
    heights, outside = [], 0
    while sim.time < 3.0 - 1e-9:
        sim.step(round(0.05 / sim.dt))
        outside = max(outside, sim.metrics()["n_outside"])
        heights.append(sim.rigid_bodies[0][1])
    assert outside == 0
    assert np.ptp(heights[-10:]) < 0.25 * sim.cell_size
    assert 0.4 < rigid.submerged(sim, rigid.water_level(sim, sim.rigid_bodies[0][0])) < 0.7


def test_the_level_from_the_waters_volume_holds_that_volume():
    """The level the buoyancy case reads from the water's volume is where the tank, less the body's part below
    it, holds Σ m/ρ: to the bisection's 1e-9 m times the tank's width (0.8 m), with a box pushed halfway into
    the water by hand and with the box above it."""
    body = {"shape": "polygon", "vertices": [[0.4, 0.30], [0.6, 0.30], [0.6, 0.4], [0.4, 0.4]], "density": 500.0}
    for vertices in (body["vertices"], BOX):
        sim = augmpm.Simulation(_scene([{**body, "vertices": vertices}]), "augmented")
        sim.step(1)
        level = rigid.level_from_volume(sim)
        held = rigid.clip_below(np.array(rigid.TANK), level) - rigid.clip_below(rigid.outline(sim), level)
        assert abs(held - np.sum(sim.masses / sim.densities)) < 2e-9
        assert 0.3 < level < 0.4


def test_a_body_out_of_reach_of_the_material_falls_freely():
    """Far from the water, a body only falls: symplectic Euler gives y = y0 − g dt² n(n+1)/2 after n steps
    and the angle ω t, to round-off."""
    disk = {"shape": "circle", "center": [0.5, 0.8], "radius": 0.05, "mass": 2.0, "angular_velocity": 1.5}
    sim = augmpm.Simulation(_scene([disk]), "augmented")
    n = 40
    sim.step(n)
    x, y, angle, vx, vy, w = sim.rigid_bodies[0]
    dt = sim.dt
    assert abs(y - (0.8 - G * dt * dt * n * (n + 1) / 2)) < 1e-12
    assert x == 0.5 and vx == 0.0 and abs(vy + G * n * dt) < 1e-12
    assert abs(angle - 1.5 * n * dt) < 1e-12 and w == 1.5


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_material_and_body_exchange_momentum_exactly(method):
    """Without gravity and with no static wall in reach, a fluid disk thrown at a free quadrilateral:
    the total linear momentum of material and body, Σ m_p v_p + m_b v_b, is conserved to round-off
    (1e-13 relative over 600 steps); so is the angular momentum about the origin, Σ (x_p × m_p v_p +
    m_p h²/4 (C_yx − C_xy)) + x_b × m_b v_b + I_b ω_b (1e-12; the augmented grid measured 1e-14: the
    wall fit's impulses count at the feet and particles carry their spin over their own grid points).
    The body is pushed: it ends up moving at more than 0.1 m/s."""
    sim = rigid.thrown_disk(method, 64, 600)
    p0, l0 = rigid.momenta(sim)
    sim.step(600)
    p1, l1 = rigid.momenta(sim)
    assert np.abs(p1 - p0).max() < 1e-13 * np.abs(p0).max()
    assert abs(l1 - l0) < 1e-12 * abs(l0)
    assert np.linalg.norm(sim.rigid_bodies[0][3:5]) > 0.1
    assert np.all(sim.wall_impulse[-1] == 0)  # the domain box was never touched


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_material_and_body_exchange_momentum_exactly_in_3d(method):
    """In 3D, without gravity and with no static wall in reach, a fluid ball thrown at a free spinning
    sphere with a sticky surface: the total linear momentum Σ m_p v_p + m_b v_b and angular momentum about
    the origin Σ (x_p × m_p v_p + m_p h²/4 axial(C_p)) + x_b × m_b v_b + I_b ω_b (I_b = 2/5 m_b r² I) are
    conserved over 300 steps within 1e-12 relative (2e-15 measured). The sphere is pushed and its spin
    changes."""
    r, density, spin = 0.08, 800.0, np.array([0.5, 1.0, -2.0])
    scene = {
        "gravity": [0.0, 0.0, 0.0],
        "wall_condition": "slip",
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": 20},
        "time": {"cfl": 0.4, "steps": 300, "output_interval": 100},
        "bodies": [
            {
                "shape": "sphere",
                "center": [0.3, 0.47, 0.5],
                "radius": 0.1,
                "velocity": [1.0, 0.1, 0.05],
                "material": {**WATER, "viscosity": 1.0},
            }
        ],
        "rigid_bodies": [
            {
                "shape": "sphere",
                "center": [0.55, 0.5, 0.5],
                "radius": r,
                "density": density,
                "angular_velocity": spin.tolist(),
                "condition": "sticky",
            }
        ],
    }
    sim = augmpm.Simulation(augmpm.Scene3.from_dict(scene), method)
    mass = density * 4 / 3 * math.pi * r**3
    inertia = 0.4 * mass * r * r

    def momenta():
        st, body = sim.checkpoint(), sim.rigid_bodies[0]
        x, v, m, c = st["x"], st["v"], st["mass"][:, None], st["c"].reshape(-1, 3, 3)
        spin_part = np.stack([c[:, 2, 1] - c[:, 1, 2], c[:, 0, 2] - c[:, 2, 0], c[:, 1, 0] - c[:, 0, 1]], axis=1)
        p = (m * v).sum(axis=0) + mass * body[6:9]
        angular = (m * np.cross(x, v)).sum(axis=0) + (m * spin_part).sum(axis=0) * sim.cell_size**2 / 4
        return p, angular + mass * np.cross(body[0:3], body[6:9]) + inertia * body[9:12]

    p0, l0 = momenta()
    sim.step(300)
    p1, l1 = momenta()
    assert np.abs(p1 - p0).max() < 1e-12 * np.abs(p0).max()
    assert np.abs(l1 - l0).max() < 1e-12 * np.linalg.norm(l0)
    body = sim.rigid_bodies[0]
    assert np.linalg.norm(body[6:9]) > 0.1 and np.linalg.norm(body[9:12] - spin) > 0.5


SNOW = {"type": "snow", "density": 400.0, "youngs_modulus": 1.4e5, "poisson_ratio": 0.2,
        "critical_compression": 2.5e-2, "critical_stretch": 7.5e-3, "hardening": 10.0}  # fmt: skip
ELASTIC = {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3}


@pytest.mark.parametrize("surface", [{"condition": "sticky"}, {"condition": "separate", "friction": 0.5},
                                     {"condition": "slip"}], ids=["sticky", "rough", "slip"])  # fmt: skip
@pytest.mark.parametrize("material", [{**WATER, "viscosity": 1.0}, SNOW, ELASTIC], ids=["fluid", "snow", "elastic"])
def test_angular_momentum_is_kept_whatever_the_surface_and_material(surface, material):
    """The angular momentum of material and body, Σ (x_p × m_p v_p + m_p h²/4 (C_yx − C_xy)) + x_b × m_b v_b +
    I_b ω_b, with the body spinning at 2 rad/s and a disk of fluid, snow or elastic material thrown at it, its
    surface sticky, rough (μ = 0.5) or slip (augmented, 48 cells, 600 steps, no gravity): conserved within
    1e-12 relative (1.2e-13 at most measured); the body's spin changes."""
    quad = [[0.5, 0.40], [0.6, 0.42], [0.58, 0.62], [0.48, 0.58]]
    scene = {
        "gravity": [0.0, 0.0],
        "grid": {"domain": [1.0, 1.0], "resolution": 48},
        "time": {"cfl": 0.4, "steps": 600, "output_interval": 100},
        "wall_condition": "slip",
        "bodies": [
            {"shape": "circle", "center": [0.3, 0.45], "radius": 0.08, "velocity": [1.0, 0.2], "material": material}
        ],
        "rigid_bodies": [{"shape": "polygon", "vertices": quad, "density": 800.0, "angular_velocity": 2.0, **surface}],
    }
    sim = augmpm.Simulation(augmpm.Scene.from_dict(scene), "augmented")
    _, l0 = rigid.momenta(sim)
    sim.step(600)
    _, l1 = rigid.momenta(sim)
    assert abs(l1 - l0) < 1e-12 * abs(l0)
    assert abs(sim.rigid_bodies[0][5] - 2.0) > 0.05


def test_a_state_with_the_bodies_kicks_of_another_scene_is_refused():
    """``body_kick`` (the velocity change each body is shown ahead) must have a row per rigid body: a state
    with another count is refused naming it, and the simulation goes on unchanged; a checkpoint written
    before it was kept (without it) restores, predicting none in the next step."""
    sim = augmpm.Simulation(_scene([{"shape": "polygon", "vertices": BOX, "density": 500.0}]))
    sim.step(10)
    state = sim.checkpoint()
    assert state["body_kick"].shape == (1, 5) and np.any(state["body_kick"] != 0)
    wrong = {**state, "body_kick": np.zeros((2, 5))}
    with pytest.raises(augmpm.SceneError, match="body_kick"):
        sim.restore(wrong)
    after = sim.checkpoint()
    assert np.array_equal(after["x"], state["x"]) and np.array_equal(after["body_kick"], state["body_kick"])
    sim.step(1)
    older = {k: v for k, v in state.items() if k != "body_kick"}
    sim.restore(older)
    assert np.all(sim.checkpoint()["body_kick"] == 0)
    sim.step(5)
    assert sim.time > state["time"]


def test_a_run_with_bodies_writes_bodies_csv_and_resumes_bitwise(tmp_path):
    """``bodies.csv`` holds one row per frame and body (its state, the material's force on it),
    the frames' npz their states; a run resumed from its checkpoint, on another thread count, writes the
    same ``metrics.csv`` and ``bodies.csv`` bytes."""
    rigid = [
        {"shape": "polygon", "vertices": BOX, "density": 500.0},
        {"shape": "circle", "center": [0.75, 0.6], "radius": 0.05, "mass": 3.0, "angular_velocity": 2.0},
    ]
    scene = _scene(rigid, resolution=32, end=0.6).model_copy(
        update={"time": _scene([]).time.model_copy(update={"end": 0.6, "output_interval": 50})}
    )
    whole = run_scene(scene, tmp_path / "whole", progress=False, checkpoint_every=3, animation=None, threads=1)
    assert whole.frames > 4
    rows = (tmp_path / "whole" / "bodies.csv").read_text().splitlines()
    assert rows[0].split(",") == ["frame", "step", "time", "body", *BODY_COLUMNS]
    assert len(rows) == 1 + 2 * whole.frames
    with np.load(tmp_path / "whole" / "particles" / "frame_00003.npz") as z:
        assert z["rigid_bodies"].shape == (2, 6)
    # The box landed on the water: the material pushed it up by the end.
    last_box = rows[-2].split(",")
    assert last_box[3] == "0" and float(last_box[BODY_COLUMNS.index("force_y") + 4]) > 0
    shutil.copytree(tmp_path / "whole", tmp_path / "again")
    resume_run(tmp_path / "again", progress=False, threads=2)
    for name in ("metrics.csv", "bodies.csv"):
        assert (tmp_path / "again" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ({"shape": "circle", "center": [0.5, 0.6], "radius": 0.05}, "rigid_bodies[0]"),
        ({"shape": "circle", "center": [0.5, 0.6], "radius": 0.05, "mass": 1.0, "density": 5.0}, "rigid_bodies[0]"),
        ({"shape": "polygon", "vertices": BOX[::-1], "density": 500.0}, "rigid_bodies[0].vertices"),
        ({"shape": "circle", "center": [0.5, 0.6], "radius": -0.05, "mass": 1.0}, "rigid_bodies[0].radius"),
        (
            {"shape": "circle", "center": [0.5, 0.6], "radius": 0.05, "mass": 1.0, "friction": 0.3},
            "rigid_bodies[0].friction",
        ),
    ],
)
def test_bad_rigid_bodies_are_refused_naming_the_key(body, key):
    """Neither or both of density and mass, a clockwise polygon, a negative radius, friction on a surface
    that is not separate: a SceneError names the key."""
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(_scene([body]))
    assert e.value.key == key


def test_a_body_is_moved_by_the_material_not_from_outside():
    """``set_wall_pose`` refuses a rigid body's wall (the engine poses it), naming ``wall``; a body
    whose velocity crosses more than a cell per step of a fixed ``time.dt`` is refused naming it."""
    sim = augmpm.Simulation(_scene([{"shape": "polygon", "vertices": BOX, "density": 500.0}]))
    with pytest.raises(augmpm.SceneError, match="rigid_bodies\\[0\\]") as e:
        sim.set_wall_pose(1, (0.0, 0.0))
    assert e.value.key == "wall"
    fast = {"shape": "circle", "center": [0.5, 0.6], "radius": 0.05, "mass": 1.0, "velocity": [100.0, 0.0]}
    scene = _scene([fast]).to_dict()
    scene["time"] = {"dt": 1e-3, "end": 0.1, "output_interval": 10}
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Simulation(augmpm.Scene.from_dict(scene))
    assert e.value.key == "rigid_bodies[0].velocity"


def test_a_state_without_the_bodies_poses_is_refused():
    """A body's state is its wall's pose: a checkpoint without it (or the wall correction of the grid
    density, computed once for still walls) is refused naming it, and the simulation goes on unchanged."""
    sim = augmpm.Simulation(_scene([{"shape": "polygon", "vertices": BOX, "density": 500.0}]))
    sim.step(10)
    state = sim.checkpoint()
    del state["wall_pose"]
    with pytest.raises(augmpm.SceneError, match="rigid_bodies\\[0\\]"):
        sim.restore(state)
    sim.step(1)
    scene = _scene([{"shape": "polygon", "vertices": BOX, "density": 500.0}]).to_dict()
    scene["grid"]["density_wall_correction"] = True
    with pytest.raises(augmpm.SceneError) as e:
        augmpm.Scene.from_dict(scene)
    assert e.value.key == "grid.density_wall_correction"


def test_a_ball_dropped_into_snow_stays_clear_of_it_and_loses_energy():
    """Impact: ``rigid/ball_into_snow`` (32 cells, 0.6 s): a 17 kg/m ball hits the snow at 2.5 m/s, bounces
    and settles on it. No snow is inside the ball at any sample (every 0.02 s), and with nothing driving
    it the total energy of snow and ball (kinetic and potential) never rises above the start's (asserted:
    never more than 0.01 J/m above) and has lost more than 10 J/m by the end (54 J/m measured; the ball
    brought 53 J/m above the snow: 45 J/m of potential and 8.5 J/m of kinetic energy)."""
    sim = rigid.shipped("ball_into_snow", "augmented", 32)
    e0 = rigid.energy(sim)
    rows = rigid.sampled(sim, 0.6)
    assert max(r[1] for r in rows) == 0
    assert max(r[2] for r in rows) - e0 < 0.01
    assert rows[-1][2] - e0 < -10.0


def test_a_piston_pushes_a_box_under_water_and_holds_it():
    """Impact: ``rigid/piston_box`` (32 cells, 1.6 s): a plate lowered 0.2 m from 0.3 s to 1.3 s meets the
    floating box (rigid contact with a moving wall) and holds it under water. No water is inside the box or
    the plate at any sample; at the end the box's top is pressed against the plate's underside (0.22 m)
    within 0.1 cell (0.03 cell measured), and once the plate stops the total energy never rises."""
    sim = rigid.shipped("piston_box", "augmented", 32)
    rows = rigid.sampled(sim, 1.6)
    assert max(r[1] for r in rows) == 0
    top = sim.rigid_bodies[0][1] + 0.04
    assert abs(top - 0.22) < 0.1 * sim.cell_size
    stopped = [e for t, _, e in rows if t >= 1.3]
    assert max(stopped) - stopped[0] < 0.01


def test_a_box_that_speeds_up_into_the_water_keeps_it_out():
    """Impact at the step's scale: the box of ``rigid/piston_box`` (64 cells) starts at rest at its draft and
    speeds up under gravity into the water below it. The material sees its wall move on at its velocity plus
    the change that gravity and contacts gave it over the last step, so no particle ends a step inside it:
    none at any sample every 0.01 s to 0.3 s. Seen at its velocities alone, the box gained Δv Δt a step on
    the water under it, and one particle was inside at 0.02 s (2e-5 cell deep)."""
    sim = rigid.shipped("piston_box", "augmented", 64)
    rows = rigid.sampled(sim, 0.3, every=0.01)
    assert max(r[1] for r in rows) == 0
    assert sim.checkpoint()["body_kick"].shape == (1, 5)


def test_a_water_wheel_turns_on_its_axle():
    """Joints: ``rigid/water_wheel`` (32 cells, 1 s): the stream turns the wheel by more than a radian while
    its centre stays on the axle (within 1e-6 m), and no water enters it."""
    sim = rigid.shipped("water_wheel", "augmented", 32)
    rows = rigid.sampled(sim, 1.0, every=0.05)
    x, y, angle = sim.rigid_bodies[0][:3]
    assert max(r[1] for r in rows) == 0
    assert abs(x - 0.6) < 1e-6 and abs(y - 0.32) < 1e-6
    assert abs(angle) > 1.0


def _tank3(rigid: list[dict], gravity: float = -G, resolution: int = 16, end: float = 0.4) -> augmpm.Scene3:
    """3D: water 0.3 m deep in a box tank turned 0.2 rad about (1, 0.2, 0.6) (slip walls), and ``rigid``."""
    return augmpm.Scene3.from_dict(_tank3_dict(rigid, gravity, resolution, end))


def _tank3_dict(rigid: list[dict], gravity: float = -G, resolution: int = 16, end: float = 0.4) -> dict:
    """The scene of :func:`_tank3` as a dict."""
    return {
        "gravity": [0.0, gravity, 0.0],
        "grid": {"domain": [1.0, 1.0, 1.0], "resolution": resolution},
        "time": {"cfl": 0.4, "end": end, "output_interval": 20},
        "wall_condition": "slip",
        "walls": [
            {"type": "box", "center": [0.5, 0.45, 0.5], "size": [0.8, 0.8, 0.8], "axis": [1, 0.2, 0.6], "angle": 0.2}
        ],
        "bodies": [
            {"shape": "box", "min": [0.0, 0.0, 0.0], "max": [1.0, 0.3, 1.0], "fill": True, "material": WATER},
        ],
        "rigid_bodies": rigid,
    }


@pytest.mark.parametrize("method", ["naive", "augmented"])
def test_3d_material_and_body_exchange_momentum_exactly(method):
    """3D, without gravity and with no static wall in reach: a fluid ball thrown at a free box turned about
    (1, 1, 0). The total linear momentum of material and body, Σ m_p v_p + m_b v_b, is conserved to
    round-off (1e-13 relative over 100 steps), and the box is pushed to more than 0.1 m/s."""
    scene = augmpm.Scene3.from_dict(
        {
            "grid": {"domain": [1, 1, 1], "resolution": 16},
            "time": {"cfl": 0.4, "steps": 100, "output_interval": 100},
            "gravity": [0, 0, 0],
            "wall_condition": "slip",
            "bodies": [
                {
                    "shape": "sphere",
                    "center": [0.3, 0.5, 0.5],
                    "radius": 0.12,
                    "velocity": [1.0, 0.2, 0.1],
                    "material": {**WATER, "viscosity": 1.0},
                }
            ],
            "rigid_bodies": [
                {"shape": "box", "center": [0.6, 0.5, 0.5], "size": [0.15, 0.2, 0.15], "axis": [1, 1, 0], "angle": 0.4,
                 "density": 800.0},
            ],
        }
    )  # fmt: skip
    sim = augmpm.Simulation(scene, method)
    mass = 800.0 * 0.15 * 0.2 * 0.15

    def momentum():
        return (sim.masses[:, None] * sim.velocities).sum(axis=0) + mass * sim.rigid_bodies[0][6:9]

    p0 = momentum()
    sim.step(100)
    assert np.abs(momentum() - p0).max() < 1e-13 * np.abs(p0).max()
    assert np.linalg.norm(sim.rigid_bodies[0][6:9]) > 0.1
    assert sim.metrics()["n_outside"] == 0 or method == "naive"


def test_a_3d_run_with_bodies_writes_bodies_csv_and_resumes_bitwise(tmp_path):
    """3D: a box and a ball half as dense as water dropped into a tilted tank; ``bodies.csv`` holds their
    states in 3D columns (rotation vectors, vectors of angular velocity, forces in N) and the frames' npz
    (rows of 12); no water is inside them; a run resumed from its checkpoint on another thread count writes
    the same ``metrics.csv`` and ``bodies.csv`` bytes."""
    spin = {"angular_velocity": [0.0, 2.0, 0.0]}
    rigid = [
        {"shape": "box", "center": [0.4, 0.42, 0.5], "size": [0.2, 0.1, 0.2], "density": 500.0},
        {"shape": "sphere", "center": [0.68, 0.45, 0.45], "radius": 0.08, "density": 500.0, **spin},
    ]
    whole = run_scene(
        _tank3(rigid), tmp_path / "whole", progress=False, checkpoint_every=2, animation=None, threads=1, render=False
    )
    assert whole.frames > 4
    rows = (tmp_path / "whole" / "bodies.csv").read_text().splitlines()
    assert rows[0].split(",") == ["frame", "step", "time", "body", *BODY_COLUMNS_3D]
    assert len(rows) == 1 + 2 * whole.frames
    with np.load(tmp_path / "whole" / "particles" / "frame_00003.npz") as z:
        assert z["rigid_bodies"].shape == (2, 12)
    metrics = (tmp_path / "whole" / "metrics.csv").read_text().splitlines()
    outside = metrics[0].split(",").index("n_outside")
    assert all(int(r.split(",")[outside]) == 0 for r in metrics[1:])
    shutil.copytree(tmp_path / "whole", tmp_path / "again")
    resume_run(tmp_path / "again", progress=False, threads=2)
    for name in ("metrics.csv", "bodies.csv"):
        assert (tmp_path / "again" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()


def test_a_dam_break_swings_a_hinged_flap_open():
    """Joints: ``rigid/hinged_flap`` (32 cells, 0.5 s): the released water swings the flap open by more
    than 0.3 rad (0.8 rad at 64 cells) while its point at the hinge stays there (within 1e-6 m), and no
    water enters it at any sample (every 0.05 s)."""
    sim = rigid.shipped("hinged_flap", "augmented", 32)
    drawn_centre = np.array([0.5, (0.0775 + 0.51) / 2])
    widest, inside, strayed = 0.0, 0, 0.0
    while sim.time < 0.5 - 1e-9:
        sim.step(max(1, round(0.05 / sim.dt)))
        x, y, angle = sim.rigid_bodies[0][:3]
        c, s = math.cos(angle), math.sin(angle)
        hinge = np.array([x, y]) + np.array([[c, -s], [s, c]]) @ (np.array([0.5, 0.5]) - drawn_centre)
        widest, inside = max(widest, abs(angle)), max(inside, sim.metrics()["n_outside"])
        strayed = max(strayed, np.abs(hinge - [0.5, 0.5]).max())
    assert inside == 0
    assert widest > 0.3
    assert strayed < 1e-6


def test_a_double_pendulum_swings_into_water_on_its_two_hinges():
    """Joints between bodies: ``rigid/double_pendulum`` (32 cells, 0.6 s): the second bar, hinged to the first
    (``hinge_to``), sweeps through the water (the water's impulse on it tops 1 N·s/m). The first bar's hinge
    stays fixed in the scene within 1e-6 m (measured: 1.2e-7 m) and the two bars' hinge points stay
    together within 1e-5 m (measured: 1.6e-6 m; the joint between two moving bodies is the looser). Nothing
    drives the scene, so its energy never rises from one sample (every 0.05 s) to the next; no water enters
    a bar at any sample."""
    sim = rigid.shipped("double_pendulum", "augmented", 32)
    drawn = [np.array([0.385, 0.7]), np.array([0.185, 0.7])]

    def carried(k, point):
        """Where body k now carries the scene's ``point`` as drawn."""
        x, y, angle = sim.rigid_bodies[k][:3]
        c, s = math.cos(angle), math.sin(angle)
        return np.array([x, y]) + np.array([[c, -s], [s, c]]) @ (np.array(point) - drawn[k])

    energy, inside, fixed, joined, rises = rigid.energy(sim), 0, 0.0, 0.0, []
    while sim.time < 0.6 - 1e-9:
        sim.step(max(1, round(0.05 / sim.dt)))
        inside = max(inside, sim.metrics()["n_outside"])
        fixed = max(fixed, np.abs(carried(0, [0.5, 0.7]) - [0.5, 0.7]).max())
        joined = max(joined, np.abs(carried(0, [0.27, 0.7]) - carried(1, [0.27, 0.7])).max())
        rises.append(rigid.energy(sim) - energy)
        energy += rises[-1]
    assert inside == 0
    assert fixed < 1e-6
    assert joined < 1e-5
    assert max(rises) <= 0.0, rises
    assert np.abs(sim.wall_impulse[len(sim.scene.walls) + 1]).max() > 1.0


@pytest.mark.parametrize(
    ("body", "key"),
    [
        ({"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05}, "rigid_bodies[0]"),
        ({"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05, "mass": 1.0, "hinge": [0.5, 0.7, 0.5]},
         "rigid_bodies[0].hinge_axis"),
        ({"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05, "mass": 1.0, "hinge_axis": [0, 0, 1]},
         "rigid_bodies[0].hinge"),
        ({"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05, "mass": 1.0, "hinge": [0.5, 0.7, 0.5],
          "hinge_axis": [0, 0, 1], "velocity": [0.1, 0, 0]}, "rigid_bodies[0].velocity"),
        ({"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05, "mass": 1.0, "hinge": [0.5, 0.7, 0.5],
          "hinge_axis": [0, 0, 1], "angular_velocity": [1.0, 0, 0]}, "rigid_bodies[0].angular_velocity"),
        ({"shape": "cylinder", "center": [0.5, 0.6, 0.5], "axis": [0, 0, 0], "radius": 0.05, "length": 0.1,
          "mass": 1.0}, "rigid_bodies[0].axis"),
        ({"shape": "box", "center": [0.5, 0.6, 0.5], "size": [0.1, 0.1, 0.1], "mass": 1.0, "friction": 0.3},
         "rigid_bodies[0].friction"),
    ],
)  # fmt: skip
def test_bad_3d_rigid_bodies_are_refused_naming_the_key(body, key):
    """A 3D rigid body without exactly one of density and mass, a hinge without its axis (or the
    reverse), a hinged body given a velocity or a spin off the hinge's axis, an axis of no length, or
    friction on a surface that is not separate: refused, naming the key."""
    with pytest.raises(augmpm.SceneError, match=re.escape(key)):
        augmpm.Simulation(_tank3([body]))


DISK = {"shape": "circle", "center": [0.5, 0.6], "radius": 0.05, "mass": 1.0}
BALL = {"shape": "sphere", "center": [0.5, 0.6, 0.5], "radius": 0.05, "mass": 1.0}


@pytest.mark.parametrize(
    ("first", "second", "key"),
    [
        (DISK, {**DISK, "hinge_to": 0}, "rigid_bodies[1].hinge_to"),
        (DISK, {**DISK, "hinge": [0.5, 0.62], "hinge_to": 1}, "rigid_bodies[1].hinge_to"),
        (DISK, {**DISK, "hinge": [0.5, 0.62], "hinge_to": 2}, "rigid_bodies[1].hinge_to"),
        (
            {**DISK, "hinge": [0.5, 0.62], "hinge_to": 1},
            {**DISK, "hinge": [0.5, 0.62], "hinge_to": 0},
            "rigid_bodies[0].hinge_to",
        ),
        (BALL, {**BALL, "hinge": [0.5, 0.62, 0.5], "hinge_axis": [0, 0, 1], "hinge_to": 1}, "rigid_bodies[1].hinge_to"),
        (BALL, {**BALL, "hinge_to": 0}, "rigid_bodies[1].hinge_to"),
    ],
)
def test_a_hinge_to_no_other_body_is_refused_naming_the_key(first, second, key):
    """``hinge_to`` without the ``hinge`` point, naming the body itself, a body the scene lacks or a body
    hinged back to this one (one hinge joins two bodies): refused, naming the key (2D and 3D)."""
    tank = _tank3 if len(first["center"]) == 3 else _scene
    with pytest.raises(augmpm.SceneError, match=re.escape(key)):
        augmpm.Simulation(tank([first, second]))


def test_a_body_hinged_to_another_carries_its_own_velocity():
    """A body hinged to another body (``hinge_to``) is given its own velocity and spin, which a hinge fixed
    in the scene refuses (there the velocity follows from the spin about the hinge; in 3D the spin must be
    along the axis): accepted, and the body starts with them as given (2D and 3D)."""
    disk = {**DISK, "hinge": [0.5, 0.62], "hinge_to": 0, "velocity": [0.1, 0.0], "angular_velocity": 2.0}
    sim = augmpm.Simulation(_scene([DISK, disk]))
    assert np.allclose(sim.rigid_bodies[1][3:], [0.1, 0.0, 2.0])
    ball = {**BALL, "hinge": [0.5, 0.62, 0.5], "hinge_axis": [0, 0, 1], "hinge_to": 0, "velocity": [0.1, 0, 0]}
    sim = augmpm.Simulation(_tank3([BALL, {**ball, "angular_velocity": [1.0, 0.0, 0.0]}]))
    assert np.allclose(sim.rigid_bodies[1][6:], [0.1, 0.0, 0.0, 1.0, 0.0, 0.0])


def test_a_body_may_be_hinged_to_one_listed_after_it():
    """``hinge_to`` may name a body later in ``rigid_bodies``: a disk hinged to a square listed after it,
    both falling freely for 0.1 s with the disk turning about the hinge, keep their hinge points together
    within 1e-6 m (the joint's tolerance in tests/rigid_contact.rs)."""
    hinge, centre, w = np.array([0.5, 0.8]), np.array([0.52, 0.78]), 6.0
    # The disk turns about the hinge, the square is still: the hinge's two points move alike.
    velocity = w * np.array([hinge[1] - centre[1], centre[0] - hinge[0]])
    disk = {"shape": "circle", "center": centre.tolist(), "radius": 0.04, "density": 800.0}
    disk |= {"hinge": hinge.tolist(), "hinge_to": 1, "angular_velocity": w, "velocity": velocity.tolist()}
    square = {"shape": "polygon", "vertices": [[0.4, 0.8], [0.5, 0.8], [0.5, 0.9], [0.4, 0.9]], "density": 500.0}
    sim = augmpm.Simulation(_scene([disk, square]))  # above the water for the 0.1 s
    drawn = [centre, np.array([0.45, 0.85])]
    apart = 0.0
    while sim.time < 0.1:
        sim.step(1)
        ends = []
        for k in range(2):
            x, y, angle = sim.rigid_bodies[k][:3]
            c, s = math.cos(angle), math.sin(angle)
            ends.append(np.array([x, y]) + np.array([[c, -s], [s, c]]) @ (hinge - drawn[k]))
        apart = max(apart, float(np.linalg.norm(ends[0] - ends[1])))
    assert apart < 1e-6


def test_a_3d_mesh_body_from_a_file_floats_with_the_mass_of_its_volume(tmp_path):
    """3D: a rigid body given as a mesh file (a cube 0.16 m across written as OBJ, its relative ``file`` read
    from the scene's folder) takes the mass of the volume the mesh encloses and, half as dense as water,
    floats like the same box given as a box: over 0.5-0.6 s the water's mean force on it is its weight
    within 10% (1.009 of it measured, on 16 cells) and the box body's within 1% (4e-5 measured), and no
    water gets inside it."""
    corners = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]  # fmt: skip
    obj = [f"v {x} {y} {z}" for x, y, z in corners] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    (tmp_path / "cube.obj").write_text("\n".join(obj) + "\n")
    cube = {"shape": "mesh", "file": "cube.obj", "scale": 0.16, "position": [0.42, 0.33, 0.42], "density": 500.0}
    box = {"shape": "box", "center": [0.5, 0.41, 0.5], "size": [0.16, 0.16, 0.16], "density": 500.0}
    forces = []
    for body in (cube, box):
        (tmp_path / "scene.toml").write_text(tomli_w.dumps(_tank3_dict([body], end=0.6)))
        sim = augmpm.Simulation(augmpm.load_scene(tmp_path / "scene.toml"), "augmented")
        first = len(sim.scene.walls)
        sim.step(round(0.5 / sim.dt))
        before, t0 = sim.wall_impulse[first].copy(), sim.time
        sim.step(round(0.1 / sim.dt))
        forces.append(-(sim.wall_impulse[first] - before)[1] / (sim.time - t0))
        assert sim.metrics()["n_outside"] == 0
    weight = 500.0 * 0.16**3 * G
    assert abs(forces[0] / weight - 1) < 0.1
    assert abs(forces[0] / forces[1] - 1) < 0.01
