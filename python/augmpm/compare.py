"""`augmpm compare`: the same scene, from the same initial particles, with the
naive and the augmented walls, side by side."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from augmpm.files import atomic_write, output_dir
from augmpm.render import write_animation
from augmpm.run import RunResult, run_scene
from augmpm.scene import Scene

METHODS = ("naive", "augmented")


@dataclass
class Comparison:
    runs: dict[str, RunResult]
    rows: list[dict[str, float]]

    def table(self) -> str:
        """A short text table: particles outside at the end and at worst, deepest penetration, run time."""
        lines = [
            f"{'method':<10} {'outside (end)':>14} {'outside (max)':>14} {'deepest (h)':>12} {'run time (s)':>13}",
        ]
        for m in METHODS:
            r = self.runs[m]
            outside = [row[f"{m}_n_outside"] for row in self.rows if f"{m}_n_outside" in row]
            deepest = max((row[f"{m}_max_penetration"] for row in self.rows if f"{m}_n_outside" in row), default=0)
            lines.append(
                f"{m:<10} {r.final_metrics['n_outside']:>14} {max(outside, default=0):>14} {deepest:>12.3f} "
                f"{r.wall_time:>13.2f}" + ("  (failed)" if r.error else "")
            )
        return "\n".join(lines)


def _read_metrics(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def compare_scene(
    scene: Scene,
    out: str | Path,
    steps: int | None = None,
    progress: bool = True,
    animation: str | None = "mp4",
    threads: int | None = None,
) -> Comparison:
    """Runs `scene` with both methods into `out/naive` and `out/augmented` and writes
    `comparison.csv`, `comparison.png` (both methods over time) and a side-by-side animation."""
    out = output_dir(out)
    runs = {
        m: run_scene(
            scene,
            out / m,
            method=m,
            steps=steps,
            progress=progress,
            animation=animation,
            threads=threads,
            raise_on_failure=False,
        )
        for m in METHODS
    }
    metrics = {m: _read_metrics(out / m / "metrics.csv") for m in METHODS}
    rows: list[dict[str, float]] = []
    for i in range(max(len(v) for v in metrics.values())):
        base = next(metrics[m][i] for m in METHODS if i < len(metrics[m]))
        row: dict[str, float] = {"step": int(base["step"]), "time": float(base["time"])}
        for m in METHODS:
            if i < len(metrics[m]):
                row[f"{m}_n_outside"] = int(metrics[m][i]["n_outside"])
                row[f"{m}_max_penetration"] = float(metrics[m][i]["max_penetration"])
        rows.append(row)
    columns = ["step", "time"] + [f"{m}_{k}" for m in METHODS for k in ("n_outside", "max_penetration")]
    with atomic_write(out / "comparison.csv", "w", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, restval="")
        writer.writeheader()
        writer.writerows(rows)
    _plot(rows, out / "comparison.png", scene.name)
    if animation:
        _side_by_side(out, animation)
    return Comparison(runs=runs, rows=rows)


def _plot(rows: list[dict[str, float]], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
    for m, colour in zip(METHODS, ("tab:red", "tab:blue"), strict=True):
        t = [r["time"] for r in rows if f"{m}_n_outside" in r]
        a.plot(t, [r[f"{m}_n_outside"] for r in rows if f"{m}_n_outside" in r], label=m, color=colour)
        b.plot(t, [r[f"{m}_max_penetration"] for r in rows if f"{m}_n_outside" in r], label=m, color=colour)
    a.set(xlabel="time (s)", ylabel="particles outside the walls", title=title)
    b.set(xlabel="time (s)", ylabel="deepest penetration (cell widths)")
    a.legend()
    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


def _side_by_side(out: Path, animation: str) -> None:
    import imageio.v2 as imageio

    frames = {m: sorted((out / m / "frames").glob("frame_*.png")) for m in METHODS}
    n = min(len(f) for f in frames.values())
    if n == 0:
        return
    joined_dir = out / "frames"
    joined_dir.mkdir(exist_ok=True)
    for stale in joined_dir.glob("frame_*.png"):
        stale.unlink()
    joined = []
    for i in range(n):
        images = [imageio.imread(frames[m][i])[..., :3] for m in METHODS]
        path = joined_dir / f"frame_{i:05d}.png"
        imageio.imwrite(path, np.hstack(images))
        joined.append(path)
    write_animation(joined, out / f"comparison.{animation}")
