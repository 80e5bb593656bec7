"""The paper's Fig. 4 interpolation test: reconstruct the distance to an inclined
wall from its values at the grid points, with the naive and the augmented grid.

The unsigned distance to the wall is sampled at the grid nodes inside the
container (0 outside) and reconstructed at every pixel by MLS from (a) all nodes
of the 3×3 stencil (naive) and (b) the included nodes plus the boundary points,
which carry the value 0 (augmented). Errors are reported within 2h of the wall.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from augmpm import _core
from augmpm.files import output_dir, save_png, write_text

# docs/paper_scenes.md, "Fig. 4: interpolation".
FIG4_POLYGON = [[0.059, 0.5], [0.941, 0.059], [0.941, 0.941], [0.059, 0.941]]


@dataclass
class InterpolationErrors:
    method: str
    resolution: int
    #: Largest and RMS absolute error within 2h of the wall and farther than 6h from
    #: every corner (where the distance field is linear), in cell widths h.
    max_error: float
    rms_error: float
    #: The same over the whole 2h band, corners included (the distance kinks there).
    max_error_with_corners: float
    rms_error_with_corners: float
    samples: int


def _walls_scene(resolution: int, polygon: list[list[float]]) -> str:
    return json.dumps(
        {
            "gravity": [0.0, 0.0],
            "grid": {"domain": [1.0, 1.0], "resolution": resolution},
            "time": {"dt": 1.0, "steps": 0, "output_interval": 1},
            "walls": [{"type": "polygon", "vertices": polygon}],
        }
    )


def reconstruct(
    method: str, resolution: int, query: np.ndarray, polygon: list[list[float]] = FIG4_POLYGON
) -> tuple[np.ndarray, np.ndarray]:
    """Reconstructed and true distance to the wall (m) at `query` (M, 2)."""
    grid = _core.Grid(_walls_scene(resolution, polygon), method)
    nodes = grid.nodes
    node_values = np.maximum(0.0, -grid.wall_distance(nodes))
    values = np.concatenate([node_values, np.zeros(len(grid.boundary_points))])
    recon, _ = grid.interpolate(values, np.ascontiguousarray(query))
    true = np.maximum(0.0, -grid.wall_distance(np.ascontiguousarray(query)))
    return recon, true


def near_wall_errors(method: str, resolution: int, pixels: int = 300) -> tuple[InterpolationErrors, np.ndarray]:
    """Errors within 2h of the wall (inside the container) on a `pixels`² raster; returns the image too."""
    h = 1.0 / resolution
    c = (np.arange(pixels) + 0.5) / pixels
    xx, yy = np.meshgrid(c, c)
    query = np.column_stack([xx.ravel(), yy.ravel()])
    recon, true = reconstruct(method, resolution, query)
    band = (true > 0) & (true < 2 * h)
    corners = np.array(FIG4_POLYGON)
    far_from_corners = np.min(np.linalg.norm(query[:, None, :] - corners[None], axis=2), axis=1) > 6 * h
    err = np.abs(recon - true) / h
    straight = err[band & far_from_corners]
    result = InterpolationErrors(
        method=method,
        resolution=resolution,
        max_error=float(straight.max()),
        rms_error=float(np.sqrt(np.mean(straight**2))),
        max_error_with_corners=float(err[band].max()),
        rms_error_with_corners=float(np.sqrt(np.mean(err[band] ** 2))),
        samples=int((band & far_from_corners).sum()),
    )
    return result, np.stack([recon.reshape(pixels, pixels), true.reshape(pixels, pixels)])


def interpolation_test(out: Path, resolution: int = 30, pixels: int = 300) -> list[InterpolationErrors]:
    """Writes `interp_test.png` (true field, naive, augmented, and their errors) and `interp_test.json`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = output_dir(out)
    results, images = [], {}
    for method in ("naive", "augmented"):
        r, img = near_wall_errors(method, resolution, pixels)
        results.append(r)
        images[method] = img
    true = images["naive"][1]
    h = 1.0 / resolution
    fig, axes = plt.subplots(2, 3, figsize=(12, 8.4), constrained_layout=True)
    panels = [("true distance", true), ("naive", images["naive"][0]), ("augmented", images["augmented"][0])]
    vmax = true.max()
    for ax, (title, img) in zip(axes[0], panels, strict=True):
        im = ax.imshow(img / h, origin="lower", extent=(0, 1, 0, 1), cmap="viridis", vmin=0, vmax=vmax / h)
        ax.set_title(f"{title} (cell widths)")
        ax.plot(*np.array([*FIG4_POLYGON, FIG4_POLYGON[0]]).T, color="w", lw=0.8)
    fig.colorbar(im, ax=axes[0], shrink=0.8)
    axes[1][0].axis("off")
    summary = "\n".join(
        f"{r.method}:\n  max {r.max_error:.2g} h, RMS {r.rms_error:.2g} h\n"
        f"  with corners: max {r.max_error_with_corners:.2g} h, RMS {r.rms_error_with_corners:.2g} h"
        for r in results
    )
    axes[1][0].text(
        0.0, 0.5, f"N = {resolution}, error within 2h of the wall,\n6h or more from corners\n\n{summary}",
        family="monospace", fontsize=9, va="center",
    )  # fmt: skip
    for ax, method in zip(axes[1][1:], ("naive", "augmented"), strict=True):
        err = np.abs(images[method][0] - true) / h
        err[true <= 0] = np.nan
        im = ax.imshow(err, origin="lower", extent=(0, 1, 0, 1), cmap="magma", vmin=0, vmax=0.5)
        ax.set_title(f"|error| {method} (cell widths)")
    fig.colorbar(im, ax=axes[1][1:], shrink=0.8)
    save_png(fig, out / "interp_test.png")
    write_text(out / "interp_test.json", json.dumps([asdict(r) for r in results], indent=2))
    return results
