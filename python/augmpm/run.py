"""A whole run: simulate a scene and write every output into a directory.

Layout of DIR: ``scene.toml`` (the resolved scene), ``metrics.csv`` (one row
per output frame), ``particles/frame_00000.npz`` (``x``, ``v``, ``body``),
``frames/frame_00000.png``, ``vtk/frame_00000.vtp`` with ``particles.pvd``,
and ``animation.mp4`` (or ``.gif``).
"""

from __future__ import annotations

import contextlib
import csv
import sys
import time as wallclock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from augmpm import _core
from augmpm.render import FrameRenderer
from augmpm.scene import Scene
from augmpm.simulation import Method, Simulation
from augmpm.vtk import write_pvd, write_vtp

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


@dataclass
class RunResult:
    out: Path
    frames: int
    final_metrics: dict[str, float]
    wall_time: float
    error: str | None = None
    warnings: list[str] = field(default_factory=list)


def run_scene(
    scene: Scene,
    out: str | Path,
    method: Method = "naive",
    steps: int | None = None,
    progress: bool = True,
    animation: str | None = "mp4",
    render: bool = True,
    threads: int | None = None,
) -> RunResult:
    """Runs ``scene`` and writes its outputs into ``out``.

    A failure of the simulation (non-finite state, a particle leaving the grid)
    stops the run; every frame written before it is kept and the result's
    ``error`` says at which step and why.
    """
    out = Path(out)
    sim = Simulation(scene, method, threads=threads)
    total = scene.time.steps if steps is None else steps
    interval = scene.time.output_interval
    out.mkdir(parents=True, exist_ok=True)
    for sub in ("particles", "frames", "vtk"):
        (out / sub).mkdir(exist_ok=True)
        # Frames of an earlier run into the same directory would mix with this one's.
        for stale in (out / sub).glob("frame_*.*"):
            stale.unlink()
    header = (
        f"# resolved scene; method = {method}, dt = {sim.dt!r} s, cell size h = {sim.cell_size!r} m, "
        f"{sim.num_particles} particles\n"
    )
    (out / "scene.toml").write_text(header + scene.to_toml(), encoding="utf-8")

    renderer = None
    if render:
        # Frames go to the animation as they are drawn, so the PNGs are not read back at the end.
        renderer = FrameRenderer(
            scene, title=f"{scene.name} ({method})", animation=out / f"animation.{animation}" if animation else None
        )
    vtk_frames: list[tuple[float, str]] = []
    error = None
    start = wallclock.perf_counter()
    bar = _progress(total, progress)
    # The renderer is closed also on an interrupt, so that the frames drawn so far make a playable animation.
    with (
        open(out / "metrics.csv", "w", newline="", encoding="utf-8") as fh,
        contextlib.closing(renderer) if renderer is not None else contextlib.nullcontext(),
    ):
        writer = csv.DictWriter(fh, fieldnames=METRIC_COLUMNS)
        writer.writeheader()

        def output(frame: int) -> None:
            m = sim.metrics()
            writer.writerow({k: m[k] for k in METRIC_COLUMNS})
            fh.flush()
            x, v, body = sim.positions, sim.velocities, sim.body
            name = f"frame_{frame:05d}"
            np.savez(out / "particles" / f"{name}.npz", x=x, v=v, body=body, time=sim.time, step=sim.steps_done)
            write_vtp(out / "vtk" / f"{name}.vtp", x, {"velocity": v, "body": body})
            vtk_frames.append((sim.time, f"vtk/{name}.vtp"))
            write_pvd(out / "particles.pvd", vtk_frames)
            if renderer is not None:
                renderer.draw(x, body, sim.time, out / "frames" / f"{name}.png")

        frame = 0
        output(frame)
        done = 0
        while done < total:
            n = min(interval, total - done)
            try:
                sim.step(n)
            except _core.SimulationError as e:
                error = str(e)
                break
            done += n
            frame += 1
            output(frame)
            bar.update(n)
    bar.close()
    return RunResult(
        out=out,
        frames=len(vtk_frames),
        final_metrics=sim.metrics(),
        wall_time=wallclock.perf_counter() - start,
        error=error,
        warnings=sim.warnings,
    )


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, enabled: bool):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, unit="step", file=sys.stderr, dynamic_ncols=True)
