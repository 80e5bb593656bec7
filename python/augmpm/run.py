"""A whole run: simulate a scene and write every output into a directory.

Layout of DIR: ``scene.toml`` (the resolved scene), ``metrics.csv`` (one row per
output frame: :data:`METRIC_COLUMNS`, then the force on each wall, :func:`wall_force_columns`, then each
rigid body's state, :func:`rigid_body_columns`), ``bodies.csv`` (with rigid bodies: one row per frame and
body, :func:`body_columns`), ``particles/frame_00000.npz`` (``x``, ``v``, ``body``; ``rigid_bodies``),
``frames/frame_00000.png``, ``vtk/frame_00000.vtp`` with ``particles.pvd`` (and the walls: ``vtk/walls/walls.vtp``,
or per frame ``vtk/walls/frame_00000.vtp`` with ``walls.pvd`` when walls move),
``animation.mp4`` (or ``.gif``), and ``checkpoint.npz`` (the state at the last
checkpoint, from which :func:`resume_run` continues).

Every file is written atomically (see :mod:`augmpm.files`). A frame's files are
written first (its PNG by the renderer's background thread), then ``metrics.csv``
with the frame's row: a row in ``metrics.csv`` means its frame is complete. A run
killed at any moment leaves complete frames, rows for all of them but the few
still being written, and a checkpoint; :func:`resume_run` removes what followed
the checkpoint and continues, writing the same bytes the uninterrupted run would
have written (the animation aside: it is encoded again from the PNG frames).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re
import sys
import time as wallclock
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from augmpm import _core
from augmpm.files import npz_bytes, output_dir, remove_stale_temporaries, write_bytes, write_npz, write_text
from augmpm.render import FrameRenderer, lower_priority, write_animation
from augmpm.scene import Scene, Scene3, _plain_error, scene_class
from augmpm.simulation import Method, Simulation
from augmpm.vtk import write_outlines_vtp, write_ply, write_pvd, write_vtp

METRIC_COLUMNS = [
    "step",
    "time",
    "kinetic_energy",
    "n_outside",
    "max_penetration",
    "ill_conditioned",
    "low_mass_nodes",
    "held_at_wall",
]


def wall_force_columns(walls: int, dim: int = 2) -> list[str]:
    """The columns of ``metrics.csv`` after :data:`METRIC_COLUMNS`: the mean force (N per metre of
    depth in 2D, N in 3D) the material put on each of ``walls`` scene walls, then on the domain box,
    over the output interval that ends at the row (0 in the first row); ``dim`` components each."""
    names = [*map(str, range(walls)), "box"]
    return [f"wall_force_{w}_{axis}" for w in names for axis in ("x", "y", "z")[:dim]]


#: What ``bodies.csv`` holds of each rigid body at each frame (2D): its centre of mass (m), its turn from
#: where the scene draws it (rad, counter-clockwise), their rates (m/s, rad/s), and the mean force (N per
#: metre of depth) the material put on it over the output interval that ends at the row (0 in the first row).
BODY_COLUMNS = ["x", "y", "angle", "vx", "vy", "angular_velocity", "force_x", "force_y"]
#: The same in 3D: the turn as a rotation vector (rad: about its direction, by its length), the angular
#: velocity as a vector (rad/s), the force in N.
BODY_COLUMNS_3D = [
    *("x", "y", "z", "angle_x", "angle_y", "angle_z", "vx", "vy", "vz"),
    *("angular_velocity_x", "angular_velocity_y", "angular_velocity_z", "force_x", "force_y", "force_z"),
]


def body_columns(dim: int) -> list[str]:
    """:data:`BODY_COLUMNS` in 2D, :data:`BODY_COLUMNS_3D` in 3D."""
    return BODY_COLUMNS if dim == 2 else BODY_COLUMNS_3D


def rigid_body_columns(bodies: int, dim: int = 2) -> list[str]:
    """The columns of ``metrics.csv`` after the wall forces: ``rigid_<k>_<c>`` for each of ``bodies`` rigid
    bodies and each column ``c`` of :func:`body_columns`."""
    return [f"rigid_{k}_{c}" for k in range(bodies) for c in body_columns(dim)]


CHECKPOINT = "checkpoint.npz"
#: Output frames between two checkpoints, unless the caller says otherwise.
CHECKPOINT_EVERY = 10
#: 2: the stable augmented transfer and the deformation density became the defaults (a format-1 run's
#: scene.toml, written without those keys, would resume with other physics).
_CHECKPOINT_FORMAT = 2
_FRAME = re.compile(r"frame_(\d+)\.")


@dataclass
class RunResult:
    out: Path
    frames: int
    final_metrics: dict[str, float]
    wall_time: float
    error: str | None = None
    warnings: list[str] = field(default_factory=list)


def run_scene(
    scene: Scene | Scene3,
    out: str | Path,
    method: Method | None = None,
    steps: int | None = None,
    progress: bool = True,
    animation: str | None = "mp4",
    render: bool = True,
    threads: int | None = None,
    checkpoint_every: int = CHECKPOINT_EVERY,
    raise_on_failure: bool = True,
) -> RunResult:
    """Runs ``scene`` and writes its outputs into ``out``.

    A failure of the simulation (non-finite state, a particle leaving the grid, an
    unstable step) stops the run; every frame written before it is kept, and the
    :class:`augmpm.SimulationError` is raised with the run's result as its ``result``
    (with ``raise_on_failure=False`` the result is returned, its ``error`` saying at
    which step and why). A checkpoint is written at the first frame and every
    ``checkpoint_every`` frames after it (0: none).
    """
    _check_every(checkpoint_every)
    sim = Simulation(scene, method, threads=threads)
    out = output_dir(out)
    scene, method = sim.scene, sim.method
    total = scene.time.total_steps(sim.dt) if steps is None else steps
    remove_stale_temporaries(out)
    # The index files of an earlier run first, so that no row ever names a removed frame.
    for name in (CHECKPOINT, "metrics.csv", "particles.pvd"):
        (out / name).unlink(missing_ok=True)
    _remove_frames_after(out, -1)
    header = (
        f"# resolved scene; method = {method}, dt = {sim.dt!r} s, cell size h = {sim.cell_size!r} m, "
        f"{sim.num_particles} particles\n"
    )
    write_text(out / "scene.toml", header + scene.to_toml())
    meta = {
        "format": _CHECKPOINT_FORMAT,
        "augmpm": _core.__version__,
        "scene": scene.to_json(),
        "method": method,
        "total_steps": total,
        "render": render,
        "animation": animation,
    }
    return _Run(sim, out, meta, checkpoint_every, progress, rows=[], done=0, frame=0, resumed=False).go(
        raise_on_failure
    )


def resume_run(
    out: str | Path,
    progress: bool = True,
    threads: int | None = None,
    checkpoint_every: int | None = None,
    raise_on_failure: bool = True,
) -> RunResult:
    """Continues the run in ``out`` from its checkpoint, with the settings it was started with; a failure
    is raised or returned as by :func:`run_scene`.

    Frames and rows after the checkpoint are removed and computed again; the frames,
    ``metrics.csv`` and ``particles.pvd`` come out bitwise identical to those of a run that
    was never interrupted, whatever the thread counts. Raises :class:`augmpm.SceneError`
    when ``out`` holds no usable checkpoint.
    """
    out = Path(out)
    meta, state = load_checkpoint(out / CHECKPOINT)
    every = meta.get("checkpoint_every", CHECKPOINT_EVERY) if checkpoint_every is None else checkpoint_every
    _check_every(every)
    try:
        data = json.loads(meta["scene"])
        scene = scene_class(data).model_validate(data)
    except ValueError as e:
        raise _plain_error("--resume", f"the checkpoint's scene is not valid: {e}") from None
    sim = Simulation(scene, meta["method"], threads=threads)
    sim.restore(state)
    frame = meta["frame"]
    rows = _read_metrics(out / "metrics.csv")
    if len(rows) <= frame:
        raise _plain_error("--resume", f"metrics.csv in {out} has {len(rows)} rows; the checkpoint is at frame {frame}")
    rows = rows[: frame + 1]
    if rows[-1].get("step") != str(sim.steps_done):
        raise _plain_error(
            "--resume", f"metrics.csv row {frame} is step {rows[-1].get('step')}; the checkpoint is at {sim.steps_done}"
        )
    remove_stale_temporaries(out)
    run = _Run(sim, out, meta, every, progress, rows=rows, done=meta["done"], frame=frame, resumed=True)
    # The index files first, then the frames after the checkpoint: no row ever names a removed frame.
    run.commit(rewrite=True)
    write_pvd(out / "particles.pvd", run.vtk_frames)
    if run.wall_frames:
        write_pvd(out / "walls.pvd", run.wall_frames)
    _remove_frames_after(out, frame)
    for partial in out.glob("*.partial.*"):
        partial.unlink()
    return run.go(raise_on_failure)


#: Frames whose files may still be waiting to be written before the run waits for the oldest. A frame's row
#: reaches the disk after the files of the frames queued before it, so a killed run leaves at most
#: 2 × 3 + 1 = 7 frames (files or PNGs) ahead of the rows in its metrics.csv: fewer than the 8 promised.
MAX_PENDING_FRAMES = 3


class _Run:
    """The loop of a run and its outputs."""

    def __init__(
        self,
        sim: Simulation,
        out: Path,
        meta: dict,
        checkpoint_every: int,
        progress: bool,
        rows: list[dict[str, str]],
        done: int,
        frame: int,
        resumed: bool,
    ) -> None:
        self.sim, self.out, self.meta = sim, out, dict(meta)
        self.meta["checkpoint_every"] = checkpoint_every
        self.every, self.progress = checkpoint_every, progress
        self.rows, self.done, self.frame, self.resumed = rows, done, frame, resumed
        # Rows of frames whose files or PNG are still being written, with their futures: committed once
        # they are.
        self.pending: deque[tuple[dict, list[Future]]] = deque()
        # The frames' files are written on a thread of their own, in order, while the simulation steps.
        self.files: ThreadPoolExecutor | None = None
        # The writes of metrics.csv and bodies.csv queued on it and not yet checked.
        self.metrics_writes: list[Future] = []
        # How many committed rows have been handed to the files' thread for metrics.csv and bodies.csv.
        self.rows_sent = 0
        # Checkpoints taken and not yet written, oldest first: (frame, state, meta). Rows lag at most
        # MAX_PENDING_FRAMES frames, so with a checkpoint every frame up to that many + 1 states wait here.
        self.checkpoints: deque[tuple[int, dict, dict]] = deque()
        self.total = int(meta["total_steps"])
        self.vtk_frames = [(float(r["time"]), f"vtk/frame_{i:05d}.vtp") for i, r in enumerate(rows)]
        # The walls of each frame (vtk/walls/, indexed by walls.pvd) when some move; still ones once
        # (vtk/walls/walls.vtp).
        outlines = sim.wall_outlines()
        # 3D walls are written and drawn as their surface points: in each frame where some move.
        self.walls_move_3d = sim.dim == 3 and (
            any(getattr(w, "motion", None) is not None for w in sim.scene.walls) or bool(sim.scene.rigid_bodies)
        )
        self.walls = any(moving for _, moving in outlines) or self.walls_move_3d
        self.columns = METRIC_COLUMNS + wall_force_columns(len(sim.wall_impulse) - 1, sim.dim)
        self.bodies = len(getattr(sim.scene, "rigid_bodies", []))
        self.columns += rigid_body_columns(self.bodies, sim.dim)
        # The text of metrics.csv and bodies.csv, grown on the files' thread (only it touches them; it never
        # touches the simulation).
        self.metrics_text = _CsvText(self.columns)
        self.body_fields = body_columns(sim.dim)
        self.bodies_text = _CsvText(["frame", "step", "time", "body", *self.body_fields])
        # The walls' impulses at the last row, from which the next row's forces are measured.
        self.impulse_at = (sim.wall_impulse.copy(), sim.time)
        self.wall_frames = [(t, f.replace("vtk/", "vtk/walls/")) for t, f in self.vtk_frames] if self.walls else []
        if (outlines or sim.dim == 3) and not self.walls:
            (out / "vtk" / "walls").mkdir(parents=True, exist_ok=True)
            self._write_walls(out / "vtk" / "walls" / "walls.vtp")
        # The per-particle fields each frame holds besides x, v and body, and whether it goes to PLY too.
        output = getattr(sim.scene, "output", None)
        self.fields = list(output.fields) if output is not None else []
        self.ply = bool(output is not None and output.ply)
        subs = ["particles", "frames", "vtk", *(["vtk/walls"] if self.walls else []), *(["ply"] if self.ply else [])]
        for sub in subs:
            (out / sub).mkdir(exist_ok=True)

    def go(self, raise_on_failure: bool) -> RunResult:
        sim, out, meta = self.sim, self.out, self.meta
        scene = sim.scene
        animation = meta["animation"] if meta["render"] else None
        renderer = None
        if meta["render"]:
            # Frames go to the animation as they are drawn, so the PNGs are not read back at the end;
            # a resumed run encodes it from the PNGs instead, as the earlier frames are not in memory.
            stream = out / f"animation.{animation}" if animation and not self.resumed else None
            outlines = [outline for outline, _ in sim.wall_outlines()]
            # 3D: the walls drawn as points on them, half a cell apart: once, or in every frame where some move.
            surface = sim.wall_points(0.5 * sim.cell_size) if sim.dim == 3 and not self.walls_move_3d else None
            title = f"{scene.name} ({sim.method})"
            renderer = FrameRenderer(scene, title=title, animation=stream, outlines=outlines, surface=surface)
        self.renderer = renderer
        error, failure = None, None
        start = wallclock.perf_counter()
        label = f"{scene.name or 'run'} ({sim.method})"
        bar = _progress(self.total, self.progress, initial=self.done, label=label)
        interval = scene.time.output_interval
        # The renderer is closed also on an interrupt, so that the frames drawn so far make a playable animation;
        # the files' thread finishes what it was given.
        files = ThreadPoolExecutor(max_workers=1, thread_name_prefix="augmpm-files", initializer=lower_priority)
        self.files = files
        with files, contextlib.closing(renderer) if renderer is not None else contextlib.nullcontext():
            if not self.resumed:
                self.output()
            while self.done < self.total:
                n = min(interval, self.total - self.done)
                try:
                    sim.step(n)
                except _core.SimulationError as e:
                    error, failure = str(e), e
                    break
                self.done += n
                self.frame += 1
                self.output()
                bar.update(n)
        bar.close()
        self.files = None
        self.commit(wait=True)
        if renderer is not None and animation and self.resumed:
            frames = sorted((out / "frames").glob("frame_*.png"), key=lambda f: int(_FRAME.match(f.name).group(1)))
            write_animation(frames, out / f"animation.{animation}")
        result = RunResult(
            out=out,
            frames=len(self.rows),
            final_metrics=sim.metrics(),
            wall_time=wallclock.perf_counter() - start,
            error=error,
            warnings=sim.warnings,
        )
        if failure is not None and raise_on_failure:
            failure.result = result
            raise failure
        return result

    def _walls_now(self, surface: np.ndarray | None = None) -> tuple[int, object]:
        """The walls where they are now, to write with :func:`_write_walls`: 2D outlines; in 3D, the walls'
        surface points half a cell apart (`surface`, if already taken)."""
        sim = self.sim
        if sim.dim == 3:
            return 3, sim.wall_points(0.5 * sim.cell_size) if surface is None else surface
        return 2, [o for o, _ in sim.wall_outlines()]

    def _write_walls(self, path: Path, surface: np.ndarray | None = None) -> None:
        """Writes the walls where they are now (:meth:`_walls_now`)."""
        _write_walls(path, self._walls_now(surface))

    def output(self) -> None:
        """Writes frame ``self.frame``: its files, then its row of ``metrics.csv``, then a checkpoint if due (the
        last two once the files are written)."""
        sim, out = self.sim, self.out
        x, v, body = sim.positions, sim.velocities, sim.body
        name = f"frame_{self.frame:05d}"
        arrays = {"x": x, "v": v, "body": body, "time": sim.time, "step": sim.steps_done}
        arrays.update(particle_fields(sim, self.fields))
        if self.bodies:
            arrays["rigid_bodies"] = sim.rigid_bodies
        self.vtk_frames.append((sim.time, f"vtk/{name}.vtp"))
        surface = sim.wall_points(0.5 * sim.cell_size) if self.walls_move_3d else None
        walls = None
        if self.walls:
            walls = self._walls_now(surface)
            self.wall_frames.append((sim.time, f"vtk/walls/{name}.vtp"))
        # What the files hold is taken now; the thread writes them while the simulation goes on.
        frame_files = [
            self._submit(
                _write_frame,
                *(out, name, arrays, list(self.vtk_frames), walls, list(self.wall_frames), self.fields, self.ply),
            )
        ]
        if self.renderer is not None:
            moving = [outline for outline, moves in sim.wall_outlines() if moves]
            if surface is not None:
                moving = [surface]
            frame_files.append(self.renderer.draw(x, body, sim.time, out / "frames" / f"{name}.png", walls=moving))
        m = sim.metrics()
        row = {k: m[k] for k in METRIC_COLUMNS}
        impulse, (last, since) = sim.wall_impulse, self.impulse_at
        force = -(impulse - last) / (sim.time - since) if sim.time > since else np.zeros_like(impulse)
        forces = self.columns[len(METRIC_COLUMNS) : len(self.columns) - len(rigid_body_columns(self.bodies, sim.dim))]
        row |= dict(zip(forces, map(float, force.ravel()), strict=True))
        if self.bodies:
            row |= self._body_columns(force)
        self.impulse_at = (impulse, sim.time)
        self.pending.append((row, frame_files))
        # Never more than a few frames behind: their arrays wait in memory until written.
        while len(self.pending) > MAX_PENDING_FRAMES:
            for f in self.pending[0][1]:
                f.result()
            self.commit()
        if self.every and self.frame % self.every == 0:
            # The state is taken now and written once this frame's row is committed (see `_write_metrics`):
            # a checkpoint is never ahead of the rows (and PNGs) it implies, and the simulation does not
            # wait for the frames still being written.
            meta = {**self.meta, "frame": self.frame, "done": self.done}
            self.checkpoints.append((self.frame, sim.checkpoint(), meta))
        self.commit()

    def _body_columns(self, force: np.ndarray) -> dict[str, float]:
        """Each rigid body's row entries: its state now, and the mean force the material put on it (its
        wall's row of ``force``, the walls' mean forces over the interval)."""
        first, columns = len(self.sim.scene.walls), body_columns(self.sim.dim)
        row = {}
        for k, state in enumerate(self.sim.rigid_bodies):
            values = [*map(float, state), *map(float, force[first + k])]
            row |= {f"rigid_{k}_{c}": v for c, v in zip(columns, values, strict=True)}
        return row

    def commit(self, wait: bool = False, rewrite: bool = False) -> None:
        """Writes ``metrics.csv`` with the rows of every frame whose files are all written (with ``wait``,
        waiting for the files and PNGs still being written, and for ``metrics.csv`` itself); ``rewrite``
        writes it even if no row is new. It is written on the files' thread after the frames' files, and then the
        latest checkpoint taken whose frame's row it holds (see :meth:`_write_metrics`)."""
        committed, failed = False, False
        try:
            while self.pending and (wait or all(f.done() for f in self.pending[0][1])):
                row, futures = self.pending[0]
                for f in futures:
                    f.result()
                self.pending.popleft()
                self.rows.append(row)
                committed = True
        except BaseException:
            # The frames before the one that failed are complete: their rows are written all the same.
            failed = True
            raise
        finally:
            self._write_metrics(committed or rewrite, wait or failed)

    def _write_metrics(self, new_rows: bool, wait: bool) -> None:
        """Writes ``metrics.csv`` (and ``bodies.csv``) with the committed rows if ``new_rows`` or if it is
        missing, on the files' thread, then queues the latest checkpoint whose frame has its row handed over
        (older ones waiting are dropped); with ``wait``, waits until these and every write queued before them
        are done. A write found failed raises its error."""
        if new_rows or not (self.out / "metrics.csv").exists():
            # The rows are formatted on the files' thread too: here only the new ones are handed over.
            first = self.rows_sent
            self.metrics_writes.append(self._submit(self._write_csv, first, self.rows[first:]))
            self.rows_sent = len(self.rows)
        # The latest checkpoint whose frame has its row handed over, written after that row on the files'
        # thread (in order); older ones are superseded.
        ready = None
        while self.checkpoints and self.checkpoints[0][0] < self.rows_sent:
            ready = self.checkpoints.popleft()
        if ready is not None:
            _, state, meta = ready
            before = list(self.metrics_writes)
            self.metrics_writes.append(self._submit(self._write_checkpoint, before, state, meta))
        if wait:
            # Everything queued before this point is written once the no-op behind it has run (one worker, in
            # order): rows committed earlier without waiting included.
            self._submit(lambda: None).result()
        # A write that failed stops the run; the finished ones are checked and let go.
        for f in [f for f in self.metrics_writes if f.done()]:
            self.metrics_writes.remove(f)
            f.result()

    def _write_checkpoint(self, before: list[Future], state: dict, meta: dict) -> None:
        """Writes a checkpoint unless one of the writes queued ``before`` it (done by now: one worker, in order)
        failed: the rows it implies would not be on disk. Runs on the files' thread."""
        if all(f.exception() is None for f in before):
            save_checkpoint(self.out / CHECKPOINT, state, meta)

    def _write_csv(self, first: int, rows: list[dict]) -> None:
        """Writes ``metrics.csv`` and ``bodies.csv`` (the rigid bodies' columns of the rows, one row per frame
        and body) with ``rows``, the committed rows from frame ``first`` on, added to those written before. Runs
        on the files' thread, in order, so that each row is formatted once."""
        columns = self.body_fields
        per_body = [
            {"frame": frame, "step": row["step"], "time": row["time"], "body": k}
            | {c: row[f"rigid_{k}_{c}"] for c in columns}
            for frame, row in enumerate(rows, start=first)
            for k in range(self.bodies)
        ]
        # Both texts are grown before either file is written: a failed write leaves them whole, for the next.
        metrics, bodies = self.metrics_text.add(rows), self.bodies_text.add(per_body)
        write_text(self.out / "metrics.csv", metrics)
        if self.bodies:
            write_text(self.out / "bodies.csv", bodies)

    def _submit(self, fn, *args) -> Future:
        """``fn(*args)`` on the files' thread (at once outside a run's loop)."""
        if self.files is None:
            done: Future = Future()
            done.set_result(fn(*args))
            return done
        return self.files.submit(fn, *args)


class _CsvText:
    """The text of a CSV file with a header and rows added in order, each row formatted once."""

    def __init__(self, fields: list[str]) -> None:
        self.fields = fields
        self.parts = [self._format(None)]

    def _format(self, rows: list[dict] | None) -> str:
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=self.fields, lineterminator="\r\n")
        if rows is None:
            writer.writeheader()
        else:
            writer.writerows(rows)
        return buf.getvalue()

    def add(self, rows: list[dict]) -> str:
        """The whole text with ``rows`` added."""
        self.parts.append(self._format(rows))
        return "".join(self.parts)


def _write_walls(path: Path, walls: tuple[int, object]) -> None:
    """The walls of :meth:`_Run._walls_now`: 2D outlines as polylines, 3D surface points as vertices."""
    dim, data = walls
    if dim == 3:
        write_vtp(path, data, {})
    else:
        write_outlines_vtp(path, data)


#: The per-particle fields a scene's ``output.fields`` may name, as a frame's arrays hold them.
OUTPUT_FIELDS = ("density", "pressure", "J", "stress", "plastic")


def particle_fields(sim: Simulation, names: list[str]) -> dict[str, np.ndarray]:
    """The fields ``names`` (of :data:`OUTPUT_FIELDS`) of the simulation's particles now: ``density``
    (ρ0 / J: kg/m², kg/m³ in 3D), ``pressure`` (−tr σ / D: N/m, Pa in 3D), ``J`` (V/V⁰: fluids ρ0/ρ with the
    density their stress sees, solids det F · J_p), ``stress`` (Cauchy, (N, D, D): N/m, Pa in 3D) and
    ``plastic`` (J_p)."""
    if not names:
        return {}
    fields = sim.particle_fields()
    out = {}
    for name in names:
        if name == "density":
            rest = np.array([b.material.density for b in sim.scene.bodies], dtype=float)
            out[name] = rest[sim.body] / fields["J"]
        elif name == "pressure":
            out[name] = -np.trace(fields["stress"], axis1=1, axis2=2) / sim.dim
        else:
            out[name] = fields[name]
    return out


def _write_frame(
    out: Path,
    name: str,
    arrays: dict,
    vtk_frames: list[tuple[float, str]],
    walls: tuple[int, object] | None,
    wall_frames: list[tuple[float, str]],
    fields: list[str] = (),
    ply: bool = False,
) -> None:
    """A frame's files: the particles' npz and VTK (and PLY), the VTK collection up to it, and where walls
    move, theirs."""
    write_npz(out / "particles" / f"{name}.npz", arrays)
    point_data = {"velocity": arrays["v"], "body": arrays["body"], **{f: arrays[f] for f in fields}}
    write_vtp(out / "vtk" / f"{name}.vtp", arrays["x"], point_data)
    if ply:
        write_ply(out / "ply" / f"{name}.ply", arrays["x"], point_data)
    write_pvd(out / "particles.pvd", vtk_frames)
    if walls is not None:
        _write_walls(out / "vtk" / "walls" / f"{name}.vtp", walls)
        write_pvd(out / "walls.pvd", wall_frames)


def save_checkpoint(path: Path, state: dict, meta: dict) -> None:
    """Writes a simulation's ``state`` (:meth:`Simulation.checkpoint`) and ``meta`` (JSON) to ``path``,
    atomically and durably."""
    arrays = {k: np.asarray(v) for k, v in state.items()}
    arrays["meta"] = np.array(json.dumps(meta))
    write_bytes(path, npz_bytes(arrays), durable=True)


def load_checkpoint(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """The ``meta`` and the state of a checkpoint written by :func:`save_checkpoint`."""
    if not path.is_file():
        raise _plain_error(
            "--resume", f"no checkpoint at {path} (the run stopped before its first one, or was not run there)"
        )
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError) as e:
        raise _plain_error("--resume", f"{path} is not a readable checkpoint: {e}") from None
    except Exception as e:  # a truncated or foreign file: EOFError, zipfile.BadZipFile, ...
        raise _plain_error("--resume", f"{path} is not a readable checkpoint ({type(e).__name__}: {e})") from None
    types = {"format": int, "scene": str, "method": str, "total_steps": int, "frame": int, "done": int}
    types |= {"render": bool, "augmpm": str}
    if (
        not isinstance(meta, dict)
        or any(not isinstance(meta.get(k), t) for k, t in types.items())
        or meta["frame"] < 0
        or meta["done"] < 0
    ):
        raise _plain_error("--resume", f"{path} is not a checkpoint augmpm wrote (its metadata is incomplete)")
    if meta["format"] != _CHECKPOINT_FORMAT or meta["augmpm"] != _core.__version__:
        raise _plain_error(
            "--resume",
            f"{path} was written by augmpm {meta['augmpm']}; this is {_core.__version__}, whose results may "
            "differ in the last bits: run the scene again",
        )
    return meta, arrays


def _check_every(every: int) -> None:
    if not isinstance(every, int) or isinstance(every, bool) or every < 0:
        raise _plain_error("checkpoint_every", f"must be a non-negative integer of frames, got {every!r}")


def _read_metrics(path: Path) -> list[dict[str, str]]:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise _plain_error("--resume", f"cannot read {path}: {e}") from None


def _remove_frames_after(out: Path, frame: int) -> None:
    """Removes the frame files numbered above ``frame`` (all of them for -1)."""
    for sub in ("particles", "frames", "vtk", "vtk/walls", "ply"):
        if (out / sub).is_dir():
            for f in (out / sub).glob("frame_*.*"):
                m = _FRAME.match(f.name)
                if m and int(m.group(1)) > frame:
                    f.unlink()


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool, initial: int = 0, label: str | None = None):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=label, unit="step", file=sys.stderr, dynamic_ncols=True)
