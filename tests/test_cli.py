"""`augmpm run` writes every promised output file, and keeps them when a run fails."""

from __future__ import annotations

import csv
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import augmpm
from augmpm.cli import main

from .conftest import SCENES


def test_short_run_of_shipped_scene_writes_every_output(tmp_path):
    out = tmp_path / "run"
    code = main(
        ["run", str(SCENES / "dam_break.toml"), "--out", str(out), "--steps", "80", "--no-progress",
         "--set", "time.output_interval=40"]
    )  # fmt: skip
    assert code == 0
    # The resolved scene loads again and is the scene that ran.
    resolved = augmpm.load_scene(out / "scene.toml")
    assert resolved.time.output_interval == 40
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[:5] == ["step", "time", "kinetic_energy", "n_outside", "max_penetration"]
    assert [int(r["step"]) for r in rows] == [0, 40, 80]
    assert float(rows[-1]["kinetic_energy"]) > 0.0
    for i in range(3):
        frame = np.load(out / "particles" / f"frame_{i:05d}.npz")
        n = len(frame["body"])
        assert frame["x"].shape == (n, 2) and frame["v"].shape == (n, 2)
        assert (out / "frames" / f"frame_{i:05d}.png").stat().st_size > 1000
        vtp = ET.parse(out / "vtk" / f"frame_{i:05d}.vtp").getroot()
        assert vtp.find("PolyData/Piece").get("NumberOfPoints") == str(n)
    pvd = ET.parse(out / "particles.pvd").getroot()
    assert [d.get("file") for d in pvd.iter("DataSet")] == [f"vtk/frame_{i:05d}.vtp" for i in range(3)]
    assert (out / "animation.mp4").stat().st_size > 1000


def test_gif_animation(small_scene, write_scene, tmp_path):
    out = tmp_path / "gif"
    assert main(["run", str(write_scene(small_scene)), "--out", str(out), "--gif", "--no-progress"]) == 0
    assert (out / "animation.gif").stat().st_size > 100
    assert not (out / "animation.mp4").exists()


def test_failed_run_exits_1_and_keeps_frames(small_scene, write_scene, tmp_path, capsys):
    small_scene["time"].update(dt=0.2, steps=400, output_interval=1)
    small_scene["bodies"][0]["material"]["youngs_modulus"] = 1e9
    out = tmp_path / "bad"
    assert main(["run", str(write_scene(small_scene)), "--out", str(out), "--no-progress", "--no-render"]) == 1
    err = capsys.readouterr().err
    assert "run failed: step" in err
    frames = sorted((out / "particles").glob("*.npz"))
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(frames) == len(rows) >= 1
    assert all(np.isfinite(np.load(f)["x"]).all() for f in frames)


def test_run_scene_raises_a_failed_run_and_keeps_its_frames(small_scene, tmp_path):
    """`augmpm.run_scene` raises SimulationError for a failed run (the step in `.step`, the run's result with
    its frame count in `.result`) after writing every frame before the failure; `raise_on_failure=False`
    returns that result instead, its `error` saying why."""
    small_scene["time"].update(dt=0.2, steps=400, output_interval=1)
    small_scene["bodies"][0]["material"]["youngs_modulus"] = 1e9
    scene = augmpm.Scene.from_dict(small_scene)
    with pytest.raises(augmpm.SimulationError) as err:
        augmpm.run_scene(scene, tmp_path / "a", progress=False, render=False)
    result = err.value.result
    assert result.error == str(err.value) and err.value.step > 0
    assert result.frames == len(list((tmp_path / "a" / "particles").glob("*.npz"))) >= 1
    quiet = augmpm.run_scene(scene, tmp_path / "b", progress=False, render=False, raise_on_failure=False)
    assert quiet.error == result.error and quiet.frames == result.frames


def test_a_frame_that_cannot_be_written_stops_the_run_with_its_rows_complete(small_scene, tmp_path, monkeypatch):
    """A frame's files are written on a thread of their own while the simulation steps on: a write that
    fails there (here the fourth frame's VTK file) still stops the run with its error, and ``metrics.csv``
    holds a row only for frames whose files were all written (the three before it)."""
    import augmpm.run

    small_scene["time"].update(steps=200, output_interval=10)
    calls = []
    write_vtp = augmpm.run.write_vtp

    def failing(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 4:
            raise OSError(28, "No space left on device")
        return write_vtp(path, *args, **kwargs)

    monkeypatch.setattr(augmpm.run, "write_vtp", failing)
    out = tmp_path / "run"
    with pytest.raises(OSError, match="No space left"):
        augmpm.run_scene(augmpm.Scene.from_dict(small_scene), out, progress=False, render=False)
    with open(out / "metrics.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == [0, 10, 20]
    assert all((out / "vtk" / f"frame_{k:05d}.vtp").is_file() for k in range(3))


def test_a_checkpoint_is_never_ahead_of_the_rows_on_disk(small_scene, tmp_path, monkeypatch):
    """``metrics.csv`` is written on the files' thread. Slowed there (a frame's files and the later
    ``metrics.csv`` writes take 0.3 s) until the run catches up on its backlog of frames and commits the
    checkpoint's frame before the checkpoint is due, every checkpoint is still saved only once the rows up to
    its frame are on disk, so a run killed just after it can resume."""
    import time

    import augmpm.run

    small_scene["time"].update(steps=100, output_interval=10)
    run = augmpm.run
    write_frame, write_text, commit = run._write_frame, run.write_text, run._Run.commit
    save_checkpoint = run.save_checkpoint
    seen = []

    def slow_frame(out, name, *args):
        if name == "frame_00001":
            time.sleep(0.3)
        return write_frame(out, name, *args)

    def slow_text(path, text, *args, **kwargs):
        if path.name == "metrics.csv" and text.count("\n") > 2:
            time.sleep(0.3)
        return write_text(path, text, *args, **kwargs)

    def late_commit(self, wait=False, rewrite=False):
        if not wait and len(self.pending) > run.MAX_PENDING_FRAMES:
            time.sleep(0.1)
        return commit(self, wait, rewrite)

    def checked(path, state, meta):
        with open(path.parent / "metrics.csv", newline="") as fh:
            seen.append((meta["frame"], len(list(csv.DictReader(fh)))))
        return save_checkpoint(path, state, meta)

    monkeypatch.setattr(run, "_write_frame", slow_frame)
    monkeypatch.setattr(run, "write_text", slow_text)
    monkeypatch.setattr(run._Run, "commit", late_commit)
    monkeypatch.setattr(run, "save_checkpoint", checked)
    checkpoint_every = run.MAX_PENDING_FRAMES + 1
    augmpm.run_scene(augmpm.Scene.from_dict(small_scene), tmp_path / "run", progress=False, render=False,
                     checkpoint_every=checkpoint_every)  # fmt: skip
    assert seen and all(rows >= frame + 1 for frame, rows in seen), seen


def test_a_checkpoint_does_not_hold_the_simulation_back(small_scene, tmp_path, monkeypatch):
    """A checkpoint waits for the frames still being written on the files' thread, not the simulation: the
    first frame's files (a checkpoint's frame) are held back until the simulation has stepped two frames past
    it, and the checkpoint still lands with the rows it implies on disk."""
    import threading

    import augmpm.run

    small_scene["time"].update(steps=60, output_interval=10)
    run = augmpm.run
    write_frame, save_checkpoint, step = run._write_frame, run.save_checkpoint, run.Simulation.step
    ahead = threading.Event()
    held, seen = [], []

    def held_frame(out, name, *args):
        if name == "frame_00000":
            # Set by the simulation's thread; were it waiting for this frame, it would never be.
            held.append(ahead.wait(timeout=20))
        return write_frame(out, name, *args)

    def stepping(self, n=1):
        step(self, n)
        if self.steps_done >= 20:
            ahead.set()

    def checked(path, state, meta):
        with open(path.parent / "metrics.csv", newline="") as fh:
            seen.append((meta["frame"], len(list(csv.DictReader(fh)))))
        return save_checkpoint(path, state, meta)

    monkeypatch.setattr(run, "_write_frame", held_frame)
    monkeypatch.setattr(run.Simulation, "step", stepping)
    monkeypatch.setattr(run, "save_checkpoint", checked)
    augmpm.run_scene(augmpm.Scene.from_dict(small_scene), tmp_path / "run", progress=False, render=False,
                     checkpoint_every=1)  # fmt: skip
    assert held == [True]
    assert seen and all(rows >= frame + 1 for frame, rows in seen), seen
    meta, _ = run.load_checkpoint(tmp_path / "run" / run.CHECKPOINT)
    assert meta["frame"] == 6


def test_a_metrics_file_that_cannot_be_written_stops_the_run(small_scene, tmp_path, monkeypatch):
    """A ``metrics.csv`` write that fails on the files' thread (the third) stops the run with its error."""
    import augmpm.run

    small_scene["time"].update(steps=200, output_interval=10)
    write_text, calls = augmpm.run.write_text, []

    def failing(path, text, *args, **kwargs):
        if path.name == "metrics.csv":
            calls.append(path)
            if len(calls) == 3:
                raise OSError(28, "No space left on device")
        return write_text(path, text, *args, **kwargs)

    monkeypatch.setattr(augmpm.run, "write_text", failing)
    with pytest.raises(OSError, match="No space left"):
        augmpm.run_scene(augmpm.Scene.from_dict(small_scene), tmp_path / "run", progress=False, render=False)


def test_a_checkpoint_is_not_written_past_a_metrics_write_that_failed(small_scene, tmp_path, monkeypatch):
    """The checkpoint queued behind a ``metrics.csv`` write that fails (the one with its frame's row) is not
    written: the run stops with the write's error, and the checkpoint on disk, if any, is of an earlier
    frame whose row is in ``metrics.csv``, so the run can still be resumed from it."""
    import augmpm.run

    small_scene["time"].update(steps=200, output_interval=10)
    run = augmpm.run
    write_text, saved = run.write_text, []
    save_checkpoint = run.save_checkpoint

    def failing(path, text, *args, **kwargs):
        # Fails the first write holding the row of frame 4 (the second checkpoint's frame, every 4).
        if path.name == "metrics.csv" and text.count("\n") > 5:
            raise OSError(28, "No space left on device")
        return write_text(path, text, *args, **kwargs)

    def recorded(path, state, meta):
        saved.append(meta["frame"])
        return save_checkpoint(path, state, meta)

    monkeypatch.setattr(run, "write_text", failing)
    monkeypatch.setattr(run, "save_checkpoint", recorded)
    out = tmp_path / "run"
    with pytest.raises(OSError, match="No space left"):
        augmpm.run_scene(augmpm.Scene.from_dict(small_scene), out, progress=False, render=False,
                         checkpoint_every=4)  # fmt: skip
    assert 4 not in saved and 8 not in saved
    with open(out / "metrics.csv", newline="") as fh:
        rows = len(list(csv.DictReader(fh)))
    assert rows <= 4
    if saved:
        meta, _ = run.load_checkpoint(out / run.CHECKPOINT)
        assert meta["frame"] < rows
        monkeypatch.setattr(run, "write_text", write_text)
        result = run.resume_run(out, progress=False)
        assert result.error is None and result.frames == 21


def test_an_output_path_that_is_a_file_is_bad_input(small_scene, tmp_path):
    """Outputs into a path that is a file (or cannot be created) raise SceneError naming `out`, not an OSError."""
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    scene = augmpm.Scene.from_dict(small_scene)
    for out in (blocker, blocker / "below"):
        with pytest.raises(augmpm.SceneError) as err:
            augmpm.run_scene(scene, out, progress=False, render=False)
        assert err.value.key == "out", str(err.value)


def test_progress_bars_name_the_scene_and_method(small_scene, tmp_path, capsys):
    """A run's progress bar says which scene and method it is (compare shows two, one per method)."""
    small_scene["name"] = "ball"
    augmpm.run_scene(augmpm.Scene.from_dict(small_scene), tmp_path, method="naive", render=False)
    assert "ball (naive)" in capsys.readouterr().err


def test_shipped_scenes_run_by_name_from_anywhere(tmp_path):
    """The scenes ship inside the package: `augmpm scenes` lists them, and `augmpm run NAME` runs one from any
    directory (here a temporary one, with the installed package); a file path still works as before."""
    listed = subprocess.run(
        [sys.executable, "-m", "augmpm", "scenes"], cwd=tmp_path, capture_output=True, text=True, check=True
    ).stdout
    names = [line.split()[0] for line in listed.splitlines()]
    assert "dam_break" in names and "paper/fluid_incline_noslip" in names
    assert len(names) == len(list(SCENES.rglob("*.toml")))
    run = [sys.executable, "-m", "augmpm", "run", "paper/fluid_incline_noslip", "--steps", "2", "--no-render"]
    p = subprocess.run([*run, "--no-progress", "--out", "out"], cwd=tmp_path, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "out" / "metrics.csv").exists()
    assert main(["run", str(SCENES / "dam_break.toml"), "--steps", "1", "--out", str(tmp_path / "file"),
                 "--no-render", "--no-progress"]) == 0  # fmt: skip


def test_console_script_is_installed(small_scene, write_scene, tmp_path):
    out = tmp_path / "cli"
    proc = subprocess.run(
        [sys.executable, "-m", "augmpm", "run", str(write_scene(small_scene)), "--out", str(out), "--no-render"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "frames in" in proc.stdout


def test_rerun_into_the_same_directory_replaces_frames(small_scene, write_scene, tmp_path):
    out = tmp_path / "again"
    scene = str(write_scene(small_scene))
    assert main(["run", scene, "--out", str(out), "--no-progress", "--set", "time.output_interval=5"]) == 0
    assert len(list((out / "particles").glob("*.npz"))) == 5
    assert main(["run", scene, "--out", str(out), "--no-progress"]) == 0
    assert len(list((out / "particles").glob("*.npz"))) == 3
    assert len(list((out / "frames").glob("*.png"))) == 3
    assert len(list((out / "vtk").glob("*.vtp"))) == 3


def test_the_method_is_a_scene_key_augmented_by_default(small_scene, write_scene, tmp_path):
    """`method` is a scene key ("augmented" unless the scene says otherwise), `--set method=...` sets it and
    `--method` overrides it; the run directory's resolved scene records the method that ran."""
    path = write_scene(small_scene)

    def ran(*args: str) -> str:
        out = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
        assert main(["run", str(path), "--out", str(out), "--steps", "2", "--no-render", "--no-progress", *args]) == 0
        resolved = (out / "scene.toml").read_text()
        header = resolved.splitlines()[0]
        assert f'method = "{header.split("method = ")[1].split(",")[0]}"' in resolved
        return header.split("method = ")[1].split(",")[0]

    assert ran() == "augmented"
    assert ran("--set", "method=naive") == "naive"
    assert ran("--set", "method=naive", "--method", "augmented") == "augmented"
    assert ran("--method", "naive") == "naive"
    assert augmpm.Simulation(augmpm.Scene.from_dict(small_scene)).method == "augmented"
    sim = augmpm.Simulation(augmpm.Scene.from_dict(small_scene), "naive")
    assert (sim.method, sim.scene.method) == ("naive", "naive")
