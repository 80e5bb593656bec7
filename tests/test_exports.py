"""Per-particle fields in a run's frames (`output.fields`: npz, VTK, PLY) and the PLY point clouds
(`output.ply`)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from plyfile import PlyData

import augmpm
from augmpm.run import particle_fields, resume_run, run_scene
from augmpm.vtk import read_vtp

ALL = ["density", "pressure", "J", "stress", "plastic"]


def test_a_fluids_stress_is_its_equation_of_state_and_viscosity():
    """A weakly compressible fluid's output stress is σ = −p I + μ(C + Cᵀ), p = k((ρ/ρ0)^γ − 1) clamped at
    min_pressure with ρ = ρ0/J, from the particles' own J and C (relative 1e-12: a few operations); its
    pressure field is −tr σ / 2; J is the particle's J (to its last bit); no plastic volume change."""
    scene = augmpm.load_scene("dam_break", ["grid.resolution=24"])
    sim = augmpm.Simulation(scene, threads=1)
    sim.step(60)
    fields = particle_fields(sim, ALL)
    state = sim.checkpoint()
    fluid = scene.bodies[0].material
    rho = fluid.density / state["jp"]
    p = np.maximum(fluid.stiffness * ((rho / fluid.density) ** fluid.gamma - 1.0), fluid.min_pressure)
    c = state["c"]
    expected = -p[:, None, None] * np.eye(2) + fluid.viscosity * (c + np.transpose(c, (0, 2, 1)))
    scale = np.abs(expected).max()
    np.testing.assert_allclose(fields["stress"], expected, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(fields["pressure"], -np.trace(fields["stress"], axis1=1, axis2=2) / 2, rtol=1e-14)
    np.testing.assert_allclose(fields["J"], state["jp"], rtol=2e-16)  # ρ0/(ρ0/J): one rounding each way
    np.testing.assert_array_equal(fields["plastic"], np.ones(sim.num_particles))
    np.testing.assert_allclose(fields["density"], fluid.density / state["jp"], rtol=4e-16)  # ρ0/J, two roundings
    assert p.max() > 100.0  # the column presses on its floor: the check is not of zeros


def test_snows_volume_ratios_are_its_deformation():
    """For snow, J = det F · J_p, the plastic field is J_p and the density ρ0 / J, from the particles' own F
    and J_p; compressed snow has J_p < 1 somewhere after it lands (its stress: the core's tests)."""
    scene = augmpm.load_scene("paper/snow_incline_fullslip")
    sim = augmpm.Simulation(scene, threads=2)
    sim.step(600)
    fields = particle_fields(sim, ["J", "plastic", "stress", "density"])
    state = sim.checkpoint()
    np.testing.assert_allclose(fields["J"], np.linalg.det(state["f"]) * state["jp"], rtol=1e-12)
    np.testing.assert_allclose(fields["density"], scene.bodies[0].material.density / fields["J"], rtol=1e-15)
    np.testing.assert_array_equal(fields["plastic"], state["jp"])
    assert fields["plastic"].min() < 1.0
    assert fields["stress"].shape == (sim.num_particles, 2, 2)


def test_a_run_writes_the_chosen_fields_to_npz_vtk_and_ply_and_resumes_them_bitwise(tmp_path):
    """With `output.fields` and `output.ply`, every frame's npz, VTK and PLY hold the fields (PLY: by
    component), the same values in each; a run resumed from a checkpoint writes the same PLY bytes."""
    overrides = ["grid.resolution=24", "time.output_interval=20", f"output.fields={ALL!r}".replace("'", '"')]
    scene = augmpm.load_scene("dam_break", [*overrides, "output.ply=true"])
    run = tmp_path / "run"
    run_scene(scene, run, steps=100, progress=False, render=False, animation=None, checkpoint_every=2)
    with np.load(run / "particles" / "frame_00005.npz") as z:
        arrays = {k: z[k] for k in z.files}
    n = len(arrays["x"])
    assert {k: arrays[k].shape for k in ALL} == {**{k: (n,) for k in ALL}, "stress": (n, 2, 2)}
    vtk = read_vtp(run / "vtk" / "frame_00005.vtp")
    for name in ("density", "pressure", "J", "plastic"):
        np.testing.assert_array_equal(vtk[name], arrays[name])
    np.testing.assert_array_equal(vtk["stress"].reshape(n, 3, 3)[:, :2, :2], arrays["stress"])
    ply = PlyData.read(str(run / "ply" / "frame_00005.ply"))["vertex"].data
    np.testing.assert_array_equal(ply["x"], arrays["x"][:, 0])
    np.testing.assert_array_equal(ply["velocity_y"], arrays["v"][:, 1])
    np.testing.assert_array_equal(ply["stress_xy"], arrays["stress"][:, 0, 1])
    np.testing.assert_array_equal(ply["body"], arrays["body"])
    np.testing.assert_array_equal(ply["z"], np.zeros(n))
    # The last checkpoint is at frame 4: a resumed copy writes frame 5 again.
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    (copy / "ply" / "frame_00005.ply").unlink()
    resume_run(copy, progress=False)
    assert (copy / "ply" / "frame_00005.ply").read_bytes() == (run / "ply" / "frame_00005.ply").read_bytes()


def test_an_unknown_output_field_is_refused():
    """A field the engine does not write is bad input naming the key."""
    with pytest.raises(augmpm.SceneError, match="output"):
        augmpm.load_scene("dam_break", ['output.fields=["vorticity"]'])
