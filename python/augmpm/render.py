"""Frames as PNG images and an animation, drawn with matplotlib (Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle, Polygon

from augmpm.scene import CircleWall, PolygonWall, Scene

_COLOURS = np.array(plt.get_cmap("tab10").colors)


def _closed_path(vertices: np.ndarray) -> matplotlib.path.Path:
    # A closed Path ignores its last vertex (the CLOSEPOLY slot), so repeat the first.
    return matplotlib.path.Path(np.vstack([vertices, vertices[:1]]), closed=True)


class FrameRenderer:
    """Draws the walls once and moves the particles for every frame."""

    def __init__(self, scene: Scene, title: str = "", size_px: int = 640) -> None:
        lx, ly = scene.grid.domain
        aspect = ly / lx
        dpi = 100
        self.fig = plt.figure(figsize=(size_px / dpi, round(size_px * aspect / 16) * 16 / dpi), dpi=dpi)
        ax = self.fig.add_axes((0, 0, 1, 1))
        ax.set_xlim(0, lx)
        ax.set_ylim(0, ly)
        ax.set_aspect("equal")
        ax.set_axis_off()
        wall_style = {"facecolor": "0.85", "edgecolor": "0.2", "linewidth": 1.5}
        ax.add_patch(plt.Rectangle((0, 0), lx, ly, fill=False, edgecolor="0.2", linewidth=2))
        for w in scene.walls:
            if isinstance(w, PolygonWall):
                # Shade the wall side: the box minus the polygon, drawn as a hole.
                outline = np.array(w.vertices)
                ax.add_patch(Polygon(outline, closed=True, fill=False, edgecolor="0.2", linewidth=1.5))
                box = np.array([[0, 0], [0, ly], [lx, ly], [lx, 0]])  # clockwise: the polygon is a hole
                path = matplotlib.path.Path.make_compound_path(_closed_path(box), _closed_path(outline))
                ax.add_patch(matplotlib.patches.PathPatch(path, facecolor="0.85", edgecolor="none", zorder=0))
            elif isinstance(w, CircleWall):
                ax.add_patch(Circle(w.center, w.radius, fill=(w.side == "outside"), **wall_style))
        self.scatter = ax.scatter([], [], s=4, linewidths=0)
        self.text = ax.text(0.01 * lx, 0.99 * ly, "", va="top", fontsize=10, family="monospace")
        self.title = title

    def draw(self, x: np.ndarray, body: np.ndarray, time: float, path: Path) -> None:
        self.scatter.set_offsets(x)
        self.scatter.set_color(_COLOURS[body % len(_COLOURS)])
        self.text.set_text(f"{self.title}  t = {time:.4f} s".strip())
        self.fig.savefig(path)

    def close(self) -> None:
        plt.close(self.fig)


def write_animation(frames: list[Path], path: Path, fps: int = 20) -> None:
    """Joins PNG frames into ``.mp4`` (ffmpeg from imageio-ffmpeg) or ``.gif``."""
    import imageio.v2 as imageio

    if path.suffix == ".gif":
        with imageio.get_writer(path, mode="I", duration=1000 / fps, loop=0) as w:
            for f in frames:
                w.append_data(imageio.imread(f))
    else:
        with imageio.get_writer(path, fps=fps, codec="libx264", quality=7, macro_block_size=16) as w:
            for f in frames:
                w.append_data(imageio.imread(f)[..., :3])
