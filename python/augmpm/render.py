"""Frames as PNG images and an animation.

matplotlib (Agg) draws the static picture (domain box, shaded wall side, wall
outlines, circles) once into an RGB array. Each frame copies that array, splats
the particles as dots with numpy and writes the caption with PIL (~1.5 ms for
1,500 particles at 640 px, where ``fig.savefig`` took ~27 ms), deflates only
the PNG row bands that differ from the background (~1.5 ms) and pipes the frame
to ffmpeg (libx264, ~3 ms), so the PNGs are never read back.

All of that runs on one background thread, at a lower CPU priority that the
ffmpeg it starts inherits, while the simulation steps (``Simulation.step``
releases the GIL). The simulation's threads leave gaps that this work fills;
at their priority it would compete with them, and a parallel step slows down
as a whole when one of its threads loses its core.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
import struct
import sys
import threading
import zlib
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from augmpm.files import write_bytes
from augmpm.scene import CircleWall, PolygonWall, PolylineWall, Scene

# matplotlib's tab10, as 8-bit RGB (a test checks them against it); particles of body b take colour b mod 10.
# Written out so that importing augmpm does not import matplotlib (~0.7 s), which only draws the walls of a
# frame's background and the field colour maps.
COLOURS = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ],
    dtype=np.uint8,
)
# A pixel belongs to a particle's dot when the pixel's centre lies within this radius (px) of the particle.
DOT_RADIUS_PX = 1.6
_DPI = 100
# Frames handed to the writer thread but not yet written: bounds how far the output lags behind.
_MAX_PENDING = 8
# Nice value of the writer thread and of the ffmpeg it starts. Measured on 2 cores (fluid_incline_noslip, naive,
# ~9 ms of output work a frame): at nice 0 the output slowed runs by 10-20%; nice 10 or 19 hid it a little better
# than 5 on an idle machine, but with both cores kept busy by other programs the writer got so little CPU that a
# run took 2.4x (nice 10) or 9x (nice 19) its time without output, where nice 5 cost 10%.
_WRITER_NICE = 5


def _closed_path(vertices: np.ndarray) -> Any:
    """A closed matplotlib Path through ``vertices``."""
    from matplotlib.path import Path as MplPath

    # A closed Path ignores its last vertex (the CLOSEPOLY slot), so repeat the first.
    return MplPath(np.vstack([vertices, vertices[:1]]), closed=True)


class _Camera:
    """An orthographic view of the 3D domain box [0, L] from the direction ``VIEW`` (up the image: +y),
    fitted into a ``width`` × ``height`` px image with a 4% margin."""

    #: From where the box is seen: right, above and in front of it.
    VIEW = np.array([0.8, 0.6, 1.5]) / np.linalg.norm([0.8, 0.6, 1.5])

    def __init__(self, extent: tuple[float, float, float], width: int, height: int) -> None:
        self.right = np.cross([0.0, 1.0, 0.0], self.VIEW)
        self.right /= np.linalg.norm(self.right)
        self.up = np.cross(self.VIEW, self.right)
        corners = np.array(
            [[i * extent[0], j * extent[1], k * extent[2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        )
        uv = np.column_stack([corners @ self.right, corners @ self.up])
        self.lo, span = uv.min(axis=0), np.ptp(uv, axis=0)
        self.scale = 0.92 * min(width / span[0], height / span[1])
        self.offset = (np.array([width, height]) - span * self.scale) / 2
        self.height = height
        depth = corners @ self.VIEW
        self.near, self.far = depth.max(), depth.min()
        self.edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
        self.corners = corners

    def to_pixel(self, x: np.ndarray) -> np.ndarray:
        """Positions (N, 3) in m to image coordinates (column, row) in px, row 0 at the top."""
        x = np.asarray(x, dtype=float).reshape(-1, 3)
        d = (np.column_stack([x @ self.right, x @ self.up]) - self.lo) * self.scale + self.offset
        return np.column_stack([d[:, 0], self.height - d[:, 1]])

    def nearness(self, x: np.ndarray) -> np.ndarray:
        """0 at the far corner of the box, 1 at the near one."""
        return np.clip(
            (np.asarray(x, dtype=float).reshape(-1, 3) @ self.VIEW - self.far) / (self.near - self.far), 0, 1
        )


def _draw_background_3d(scene: Any, size_px: int, walls: np.ndarray | None) -> tuple[np.ndarray, _Camera]:
    """A 3D frame's background: white, the domain box's edges and the walls' surface points (grey, darker
    nearer the viewer); and its camera."""
    width, height = size_px, (size_px // 16) * 16
    camera = _Camera(tuple(scene.grid.domain), width, height)
    canvas = Image.new("RGB", (width, height), (255, 255, 255))
    pen = ImageDraw.Draw(canvas)
    if walls is not None and len(walls):
        order = np.argsort(camera.nearness(walls))
        p, grey = camera.to_pixel(walls[order]), (215 - 70 * camera.nearness(walls[order])).astype(int)
        for (c, r), g in zip(p, grey, strict=True):
            pen.point((float(c), float(r)), fill=(int(g), int(g), int(g)))
    corners = camera.to_pixel(camera.corners)
    for a, b in camera.edges:
        pen.line([tuple(corners[a]), tuple(corners[b])], fill=(51, 51, 51), width=1)
    return np.asarray(canvas).copy(), camera


def image_size(scene: Scene, size_px: int = 640) -> tuple[int, int]:
    """(width, height) of a frame in px; the height is rounded to a multiple of 16, which libx264 accepts."""
    lx, ly = scene.grid.domain
    return size_px, max(16, round(size_px * ly / lx / 16) * 16)


def _draw_background(
    scene: Scene, size_px: int, outlines: list[np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The walls drawn by matplotlib: RGB image (H, W, 3) and the world → display map (px per m, offset px).
    A polyline wall is drawn from its outline in ``outlines`` (one per wall, from
    ``Simulation.wall_outlines``), else as its segments and round joints."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle, PathPatch, Polygon, Rectangle
    from matplotlib.path import Path as MplPath

    lx, ly = scene.grid.domain
    width, height = image_size(scene, size_px)
    fig = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, lx)
    ax.set_ylim(0, ly)
    ax.set_aspect("equal")
    ax.set_axis_off()
    wall_style = {"facecolor": "0.85", "edgecolor": "0.2", "linewidth": 1.5}
    ax.add_patch(Rectangle((0, 0), lx, ly, fill=False, edgecolor="0.2", linewidth=2))
    for i, w in enumerate(scene.walls):
        if w.motion is not None:
            continue  # a moving wall is drawn on each frame, where it is then
        if isinstance(w, PolygonWall) and w.side == "outside":
            ax.add_patch(Polygon(np.array(w.vertices), closed=True, **wall_style))
        elif isinstance(w, PolygonWall):
            # Shade the wall side: the box minus the polygon, drawn as a hole.
            outline = np.array(w.vertices)
            ax.add_patch(Polygon(outline, closed=True, fill=False, edgecolor="0.2", linewidth=1.5))
            box = np.array([[0, 0], [0, ly], [lx, ly], [lx, 0]])  # clockwise: the polygon is a hole
            path = MplPath.make_compound_path(_closed_path(box), _closed_path(outline))
            ax.add_patch(PathPatch(path, facecolor="0.85", edgecolor="none", zorder=0))
        elif isinstance(w, CircleWall):
            ax.add_patch(Circle(w.center, w.radius, fill=(w.side == "outside"), **wall_style))
        elif isinstance(w, PolylineWall) and outlines is not None:
            ax.add_patch(Polygon(np.asarray(outlines[i]), closed=True, **wall_style))
        elif isinstance(w, PolylineWall):
            fill = {"facecolor": "0.85", "edgecolor": "none"}
            half, points = 0.5 * w.thickness, np.asarray(w.vertices, dtype=float)
            for a, b in itertools.pairwise(points):
                n = np.array([a[1] - b[1], b[0] - a[0]]) / np.hypot(*(b - a)) * half
                ax.add_patch(Polygon(np.array([a + n, b + n, b - n, a - n]), closed=True, **fill))
            for p in points:
                ax.add_patch(Circle(p, half, **fill))
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    if rgb.shape != (height, width, 3):
        raise RuntimeError(f"matplotlib drew {rgb.shape[1]} x {rgb.shape[0]} px, not {width} x {height}")
    # transData is final only after the draw, which applies the equal aspect (the axes shrink to fit
    # when the height was rounded). Display coordinates are px from the bottom-left corner.
    corners = ax.transData.transform([[0.0, 0.0], [lx, ly]])
    scale = (corners[1] - corners[0]) / np.array([lx, ly])
    return rgb, scale, corners[0]


def _png(width: int, height: int, zlib_stream: bytes) -> bytes:
    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8 bits, colour type 2 (RGB)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib_stream) + chunk(b"IEND", b"")


def _png_rows(rgb: np.ndarray) -> bytes:
    """PNG scanlines of an RGB image (H, W, 3): each row prefixed with filter type 0 (None)."""
    h, w, _ = rgb.shape
    raw = np.zeros((h, 1 + 3 * w), dtype=np.uint8)
    raw[:, 1:] = rgb.reshape(h, 3 * w)
    return raw.tobytes()


class _BandPng:
    """PNG encoder for frames that differ from one background in a few bands of rows.

    The zlib stream is cut into bands of ``BAND`` rows, each deflated on its own and ended
    with a sync flush (byte-aligned, not final), so bands that match the background reuse
    its compressed bytes; in a flow scene over half the rows do (the ``pigz`` construction:
    zlib header, the bands, an empty final block, Adler-32 of all the rows).
    """

    BAND = 16

    def __init__(self, background: np.ndarray) -> None:
        self.height, self.width = background.shape[:2]
        self._rows = [_png_rows(background[r : r + self.BAND]) for r in range(0, self.height, self.BAND)]
        self._deflated = [self._deflate(rows) for rows in self._rows]

    @staticmethod
    def _deflate(rows: bytes) -> bytes:
        c = zlib.compressobj(1, zlib.DEFLATED, -15)  # raw deflate: no header, no checksum
        return c.compress(rows) + c.flush(zlib.Z_SYNC_FLUSH)

    def encode(self, rgb: np.ndarray, changed: np.ndarray) -> bytes:
        """The PNG of ``rgb``, equal to the background outside the bands where ``changed`` (one bool a band)."""
        parts, adler = [b"\x78\x01"], 1  # zlib header: deflate, 32 KiB window, fastest
        for b, band_changed in enumerate(changed):
            if band_changed:
                rows = _png_rows(rgb[b * self.BAND : (b + 1) * self.BAND])
                parts.append(self._deflate(rows))
            else:
                rows = self._rows[b]
                parts.append(self._deflated[b])
            adler = zlib.adler32(rows, adler)
        parts += [b"\x03\x00", struct.pack(">I", adler)]  # empty final block (fixed Huffman), checksum
        return _png(self.width, self.height, b"".join(parts))


def _draw_key(img: np.ndarray, key: list[tuple[str, np.ndarray]], font: Any) -> None:
    """A legend at the top right of ``img``: a square of each colour and its label."""
    canvas = Image.fromarray(img)
    pen = ImageDraw.Draw(canvas)
    width = max(font.getbbox(label)[2] for label, _ in key) + 24
    left, top = img.shape[1] - width - 8, 8
    pen.rectangle((left - 4, top - 4, left + width, top + 18 * len(key)), fill=(255, 255, 255), outline=(120,) * 3)
    for k, (label, colour) in enumerate(key):
        y = top + 18 * k
        pen.rectangle((left, y + 2, left + 12, y + 14), fill=tuple(int(c) for c in colour))
        pen.text((left + 18, y), label, fill=(0, 0, 0), font=font)
    img[...] = np.asarray(canvas)


#: The colour map of a field (`augmpm render --colour-by`).
FIELD_CMAP = "viridis"


def field_colours(values: np.ndarray, low: float, high: float) -> np.ndarray:
    """RGB (N, 3) uint8 of ``values`` on :data:`FIELD_CMAP` between ``low`` and ``high`` (clipped)."""
    import matplotlib

    span = high - low if high > low else 1.0
    t = np.clip((np.asarray(values, dtype=float) - low) / span, 0.0, 1.0)
    return np.round(matplotlib.colormaps[FIELD_CMAP](np.nan_to_num(t))[:, :3] * 255).astype(np.uint8)


def _draw_colour_bar(img: np.ndarray, label: str, low: float, high: float, font: Any) -> None:
    """A vertical colour bar at the right of ``img`` from ``low`` (bottom) to ``high`` (top), labelled."""
    h, w = img.shape[:2]
    bar_h, bar_w = max(40, h // 3), 14
    right = w - 8
    top = 48  # below the caption
    texts = [f"{high:.3g}", f"{low:.3g}"]
    text_w = max(font.getbbox(t)[2] for t in [*texts, label])
    left = right - bar_w - text_w - 10
    canvas = Image.fromarray(img)
    pen = ImageDraw.Draw(canvas)
    pen.rectangle((left - 6, top - 24, right + 2, top + bar_h + 6), fill=(255, 255, 255), outline=(120,) * 3)
    pen.text((left, top - 20), label, fill=(0, 0, 0), font=font)
    ramp = field_colours(np.linspace(high, low, bar_h), low, high)
    img2 = np.asarray(canvas).copy()
    img2[top : top + bar_h, left : left + bar_w] = ramp[:, None, :]
    canvas = Image.fromarray(img2)
    pen = ImageDraw.Draw(canvas)
    pen.rectangle((left, top, left + bar_w, top + bar_h), outline=(51,) * 3)
    pen.text((left + bar_w + 6, top - 2), texts[0], fill=(0, 0, 0), font=font)
    pen.text((left + bar_w + 6, top + bar_h - 14), texts[1], fill=(0, 0, 0), font=font)
    img[...] = np.asarray(canvas)


def lower_priority() -> None:
    """Lowers the calling thread's CPU priority to nice ``_WRITER_NICE``; processes it starts inherit it."""
    # Linux only: there the nice value is per thread and PRIO_PROCESS with a thread id sets just that thread's.
    # Elsewhere the same call would take the id for a process's and renice the whole program, or another one.
    if sys.platform == "linux":
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), _WRITER_NICE)


def _open_writer(path: Path, fps: int):
    """An imageio writer for ``.gif`` or ``.mp4`` (libx264 through imageio-ffmpeg) at ``fps`` frames per second."""
    import imageio.v2 as imageio

    if path.suffix == ".gif":
        return imageio.get_writer(path, mode="I", duration=1000 / fps, loop=0)
    # quality 7 is crf 15, as before. Preset ultrafast: ~3 ms a 640 px frame instead of ~13 (medium), and
    # no 40-frame look-ahead for close() to wait on; the price is a file about twice as large (~2 MB for 100 frames).
    return imageio.get_writer(
        path, fps=fps, codec="libx264", quality=7, macro_block_size=16, ffmpeg_params=["-preset", "ultrafast"]
    )


class FrameRenderer:
    """Draws the walls once and splats the particles onto a copy for every frame.

    With ``animation`` (a ``.mp4`` or ``.gif`` path) every frame is appended to that
    animation too. It is written under a ``.partial`` name and takes its own name in
    :meth:`close`, so a killed run leaves no truncated file under the final name.
    A frame is drawn and written by a background thread at low priority, at most a few
    frames behind :meth:`draw`; :meth:`close` waits for them and raises what failed there.
    """

    def __init__(
        self,
        scene: Scene,
        title: str = "",
        size_px: int = 640,
        animation: Path | None = None,
        fps: int = 20,
        outlines: list[np.ndarray] | None = None,
        surface: np.ndarray | None = None,
        key: list[tuple[str, np.ndarray]] | None = None,
        colour_bar: tuple[str, float, float] | None = None,
    ) -> None:
        self._camera: _Camera | None = None
        if len(scene.grid.domain) == 3:
            # 3D: seen from one side (orthographic), the walls as their surface points (``surface``, (P, 3)
            # m), particles shaded by depth and drawn far to near.
            self.background, self._camera = _draw_background_3d(scene, size_px, surface)
            self._filled = []
            self._text_at = (6.0, 4.0)
        else:
            self.background, self._scale, self._offset = _draw_background(scene, size_px, outlines)
            # Which moving walls are obstacles (material outside them; a polyline always): drawn filled, as
            # the still ones.
            self._filled = [getattr(w, "side", "outside") == "outside" for w in scene.walls if w.motion is not None]
            lx, ly = scene.grid.domain
            # The caption's top-left corner at (0.01 lx, 0.99 ly), as before; 14 px is 10 pt at 100 dpi.
            self._text_at = tuple(self.to_pixel(np.array([[0.01 * lx, 0.99 * ly]]))[0])
        self.title = title
        self._font = ImageFont.load_default(size=14)
        if key:
            _draw_key(self.background, key, self._font)
        if colour_bar is not None:
            _draw_colour_bar(self.background, *colour_bar, self._font)
        # Offsets from a particle's pixel to the pixels whose centre can lie within DOT_RADIUS_PX of it.
        r = int(np.ceil(DOT_RADIUS_PX))
        dr, dc = np.mgrid[-r : r + 1, -r : r + 1]
        reach = np.maximum(np.abs(dr) - 0.5, 0) ** 2 + np.maximum(np.abs(dc) - 0.5, 0) ** 2 <= DOT_RADIUS_PX**2
        self._dr, self._dc = dr[reach], dc[reach]
        self._png = _BandPng(self.background)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="augmpm-frames", initializer=lower_priority)
        self._pending: deque[Future] = deque()
        self._animation = None
        self._animation_frames = 0
        if animation is not None:
            animation = Path(animation)
            self._animation_path = animation
            self._animation_partial = animation.with_name(f"{animation.stem}.partial{animation.suffix}")
            self._animation = _open_writer(self._animation_partial, fps)

    def to_pixel(self, x: np.ndarray) -> np.ndarray:
        """World positions (N, 2), or (N, 3) in 3D, in m to image coordinates (column, row) in px, row 0 at
        the top."""
        if self._camera is not None:
            return self._camera.to_pixel(x)
        d = np.asarray(x, dtype=float).reshape(-1, 2) * self._scale + self._offset
        return np.column_stack([d[:, 0], self.background.shape[0] - d[:, 1]])

    def image(self, x: np.ndarray, body: np.ndarray, time: float) -> np.ndarray:
        """The frame as an RGB array (H, W, 3): background, particles at ``x`` (N, 2) in m by body, caption."""
        return self._compose(x, body, time)[0]

    def _compose(
        self,
        x: np.ndarray,
        body: np.ndarray,
        time: float,
        walls: list[np.ndarray] | None = None,
        colours: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The frame, and which bands of ``_BandPng.BAND`` rows it changed from the background."""
        img = self.background.copy()
        h, w = img.shape[:2]
        changed = np.zeros(-(-h // _BandPng.BAND), dtype=bool)
        if walls and self._camera is not None:
            # 3D: the walls' surface points where they are now, grey, darker nearer the viewer.
            top, bottom = self._surface(img, np.vstack(walls))
            changed[top // _BandPng.BAND : -(-bottom // _BandPng.BAND)] = True
        elif walls:
            top, bottom = self._outlines(img, walls)
            changed[top // _BandPng.BAND : -(-bottom // _BandPng.BAND)] = True
        dim = 3 if self._camera is not None else 2
        x = np.asarray(x, dtype=float).reshape(-1, dim)
        finite = np.isfinite(x).all(axis=1)
        colours = COLOURS[np.asarray(body)[finite] % len(COLOURS)] if colours is None else colours[finite]
        x = x[finite]
        if self._camera is not None:
            # Far to near, so that the nearer particles cover the farther; farther ones darker.
            near = self._camera.nearness(x)
            order = np.argsort(near, kind="stable")
            x, near = x[order], near[order]
            colours = (colours[order] * (0.45 + 0.55 * near)[:, None]).astype(np.uint8)
        p = self.to_pixel(x)
        base = np.floor(p)
        frac = p - base  # position inside the particle's pixel, in [0, 1)
        d2 = (self._dc + 0.5 - frac[:, :1]) ** 2 + (self._dr + 0.5 - frac[:, 1:]) ** 2
        i, k = np.nonzero(d2 <= DOT_RADIUS_PX**2)
        cols = base[i, 0].astype(np.int64) + self._dc[k]
        rows = base[i, 1].astype(np.int64) + self._dr[k]
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        rows, cols = rows[inside], cols[inside]
        img.reshape(-1, 3)[rows * w + cols] = colours[i[inside]]
        changed[rows // _BandPng.BAND] = True
        top, bottom = self._caption(img, f"{self.title}  t = {time:.4f} s".strip())
        changed[top // _BandPng.BAND : -(-bottom // _BandPng.BAND)] = True
        return img, changed

    def _surface(self, img: np.ndarray, points: np.ndarray) -> tuple[int, int]:
        """Draws 3D wall points (N, 3) in m as single grey pixels, as the background draws still walls;
        returns the rows it may have changed, [top, bottom)."""
        h, w = img.shape[:2]
        near = self._camera.nearness(points)
        order = np.argsort(near, kind="stable")
        p = np.floor(self._camera.to_pixel(points[order])).astype(np.int64)
        grey = (215 - 70 * near[order]).astype(np.uint8)
        inside = (p[:, 1] >= 0) & (p[:, 1] < h) & (p[:, 0] >= 0) & (p[:, 0] < w)
        rows, cols = p[inside, 1], p[inside, 0]
        img.reshape(-1, 3)[rows * w + cols] = grey[inside, None]
        return (int(rows.min()), int(rows.max()) + 1) if len(rows) else (0, 0)

    def _outlines(self, img: np.ndarray, walls: list[np.ndarray]) -> tuple[int, int]:
        """Draws each closed outline (world coordinates, m) in dark grey, 2 px wide; returns the rows it
        may have changed, [top, bottom)."""
        canvas = Image.fromarray(img)
        pen = ImageDraw.Draw(canvas)
        top, bottom = img.shape[0], 0
        for k, outline in enumerate(walls):
            p = self.to_pixel(outline)
            if k < len(self._filled) and self._filled[k]:
                pen.polygon([tuple(q) for q in p], fill=(217, 217, 217))
            pen.line([tuple(q) for q in np.vstack([p, p[:1]])], fill=(51, 51, 51), width=2)
            top, bottom = min(top, int(p[:, 1].min()) - 2), max(bottom, int(p[:, 1].max()) + 3)
        img[...] = np.asarray(canvas)
        return max(top, 0), min(max(bottom, 0), img.shape[0])

    def _caption(self, img: np.ndarray, text: str) -> tuple[int, int]:
        """Writes ``text`` in black at the top left; returns the rows it may have changed, [top, bottom)."""
        # PIL draws the text as coverage into a small greyscale image, blended here in black: converting
        # the whole frame to a PIL image and back would copy it twice.
        _, _, right, bottom = self._font.getbbox(text)
        mask = Image.new("L", (max(right, 1), max(bottom, 1)))
        ImageDraw.Draw(mask).text((0, 0), text, fill=255, font=self._font)
        c0, r0 = (max(0, round(v)) for v in self._text_at)
        region = img[r0 : r0 + mask.height, c0 : c0 + mask.width]
        alpha = np.asarray(mask)[: region.shape[0], : region.shape[1], None].astype(np.uint16)
        region[...] = (region * (255 - alpha) // 255).astype(np.uint8)
        return r0, r0 + region.shape[0]

    def draw(
        self,
        x: np.ndarray,
        body: np.ndarray,
        time: float,
        path: Path,
        walls: list[np.ndarray] | None = None,
        colours: np.ndarray | None = None,
    ) -> Future:
        """Draws particles ``x`` (N, 2) in m at ``time`` (s) into the PNG at ``path`` and the animation,
        with the outlines ``walls`` ((M, 2) arrays in m: the moving walls where they are then), coloured by
        body, or by ``colours`` (N, 3) uint8 RGB.

        Returns once the frame is queued, with the future of its writing; the arrays are copied,
        so the caller may reuse them.
        """
        outlines = [np.array(w, dtype=float) for w in walls or []]
        rgb = None if colours is None else np.array(colours, dtype=np.uint8)
        frame = (np.array(x, dtype=float), np.array(body), float(time), Path(path), outlines, rgb)
        future = self._pool.submit(self._write, *frame)
        self._pending.append(future)
        while len(self._pending) > _MAX_PENDING:
            self._pending.popleft().result()
        return future

    def _write(
        self,
        x: np.ndarray,
        body: np.ndarray,
        time: float,
        path: Path,
        walls: list[np.ndarray],
        colours: np.ndarray | None = None,
    ) -> None:
        img, changed = self._compose(x, body, time, walls, colours)
        write_bytes(path, self._png.encode(img, changed))
        if self._animation is not None:
            self._animation.append_data(img)
            self._animation_frames += 1

    def flush(self) -> None:
        """Waits until every frame drawn so far is written."""
        while self._pending:
            self._pending.popleft().result()

    def close(self) -> None:
        """Waits for every frame's files, then finishes the animation and moves it to its own name."""
        try:
            while self._pending:
                self._pending.popleft().result()
        finally:
            self._pool.shutdown(wait=True, cancel_futures=True)
            if self._animation is not None:
                self._animation.close()
                self._animation = None
                # With no frame the writers write no file, and no animation is promised.
                if self._animation_frames > 0:
                    self._animation_partial.replace(self._animation_path)


def write_animation(frames: list[Path], path: Path, fps: int = 20) -> None:
    """Joins PNG frames into ``.mp4`` (ffmpeg from imageio-ffmpeg) or ``.gif``, written under a
    ``.partial`` name and renamed when complete."""
    import imageio.v2 as imageio

    partial = path.with_name(f"{path.stem}.partial{path.suffix}")
    with _open_writer(partial, fps) as w:
        for f in frames:
            img = imageio.imread(f)
            w.append_data(img if path.suffix == ".gif" else img[..., :3])
    partial.replace(path)


#: Units of the fields `augmpm render --colour-by` knows; any other per-particle array of a frame is drawn
#: too, labelled with its name.
FIELD_UNITS = {"speed": "m/s", "vx": "m/s", "vy": "m/s", "vz": "m/s"}
#: Units of the output fields (`output.fields`) in 2D and in 3D.
FIELD_UNITS_2D = {"density": "kg/m²", "pressure": "N/m", "J": "1", "plastic": "1"}
FIELD_UNITS_3D = {"density": "kg/m³", "pressure": "Pa", "J": "1", "plastic": "1"}


def _field(frame: Any, name: str) -> np.ndarray:
    """A per-particle scalar of a frame's arrays: ``speed``, ``vx``/``vy``/``vz`` or a stored (N,) array."""
    if name == "speed":
        return np.linalg.norm(frame["v"], axis=1)
    if name in ("vx", "vy", "vz"):
        return frame["v"][:, "xyz".index(name[1])]
    return np.asarray(frame[name], dtype=float)


def render_run(
    run_dir: str | Path,
    out: str | Path | None = None,
    size_px: int = 640,
    fps: int = 20,
    colour_by: str = "body",
    animation: str = "mp4",
) -> tuple[Path, int]:
    """Draws the frames of the finished (or interrupted) run in ``run_dir`` again, without running it:
    PNGs into ``out/frames/`` (default ``run_dir/render``) and ``out/animation.<animation>``, ``size_px``
    wide at ``fps`` frames per second, the particles coloured by body (with a legend of the bodies'
    materials) or by the field ``colour_by`` (with a colour bar over its range in all frames). Returns the
    directory and the number of frames; bad input raises :class:`augmpm.SceneError` naming the option."""
    from augmpm.files import output_dir
    from augmpm.scene import _plain_error, load_scene
    from augmpm.vtk import read_outlines

    run_dir = Path(run_dir)
    if not (run_dir / "scene.toml").is_file() or not (run_dir / "particles").is_dir():
        raise _plain_error("RUN_DIR", f"{run_dir} is not a run directory (no scene.toml and particles/)")
    if not 64 <= size_px <= 8192:
        raise _plain_error("--size", f"must lie in [64, 8192] px, got {size_px}")
    if not 1 <= fps <= 240:
        raise _plain_error("--fps", f"must lie in [1, 240], got {fps}")
    if animation not in ("mp4", "gif"):
        raise _plain_error("--animation", f"must be mp4 or gif, got {animation!r}")
    scene = load_scene(run_dir / "scene.toml")
    frames = sorted((run_dir / "particles").glob("frame_*.npz"))
    if not frames:
        raise _plain_error("RUN_DIR", f"{run_dir / 'particles'} holds no frame")
    dim = len(scene.grid.domain)
    key, bar, low, high = None, None, 0.0, 1.0
    if colour_by == "body":
        names = [getattr(b, "name", None) or b.material.type for b in scene.bodies]
        key = [(f"body {k}: {name}", COLOURS[k % len(COLOURS)]) for k, name in enumerate(names)]
    else:
        values = []
        for f in frames:
            with np.load(f) as z:
                known = ["body", *FIELD_UNITS][: 4 + (dim == 3)]
                stored = [k for k in z.files if z[k].shape == z["body"].shape and k != "body"]
                if colour_by not in known + stored:
                    raise _plain_error(
                        "--colour-by", f"{colour_by!r} is not a field of the frames ({', '.join(known + stored)})"
                    )
                v = _field(z, colour_by)
                values.append(v[np.isfinite(v)])
        every = np.concatenate(values) if values else np.zeros(1)
        low, high = (float(every.min()), float(every.max())) if every.size else (0.0, 1.0)
        unit = {**FIELD_UNITS, **(FIELD_UNITS_3D if dim == 3 else FIELD_UNITS_2D)}.get(colour_by)
        bar = (f"{colour_by} ({unit})" if unit else colour_by, low, high)
    moving = [w.motion is not None for w in scene.walls] + [True] * len(getattr(scene, "rigid_bodies", []))
    walls_move = (run_dir / "walls.pvd").exists()
    still = run_dir / "vtk" / "walls" / "walls.vtp"
    outlines = surface = None
    if still.exists():
        if dim == 3:
            surface = read_outlines(still, 3)[0]
        else:
            outlines = read_outlines(still)
    elif walls_move and dim == 2:
        first = run_dir / "vtk" / "walls" / frames[0].with_suffix(".vtp").name
        outlines = read_outlines(first) if first.exists() else None
    out = output_dir(run_dir / "render" if out is None else out, "--out")
    (out / "frames").mkdir(exist_ok=True)
    # As the run titled its frames: the scene's name and the method, which scene.toml's first line gives.
    header = (run_dir / "scene.toml").read_text(encoding="utf-8").partition("\n")[0]
    method = re.search(r"method = (\w+)", header)
    title = f"{scene.name or run_dir.name}" + (f" ({method.group(1)})" if method else "")
    title += "" if colour_by == "body" else f": {colour_by}"
    renderer = FrameRenderer(
        scene,
        title=title,
        size_px=size_px,
        animation=out / f"animation.{animation}",
        fps=fps,
        outlines=outlines,
        surface=surface,
        key=key,
        colour_bar=bar,
    )
    with contextlib.closing(renderer):
        for f in frames:
            with np.load(f) as z:
                x, body, time = z["x"], z["body"], float(z["time"])
                colours = None if colour_by == "body" else field_colours(_field(z, colour_by), low, high)
            walls = None
            wall_file = run_dir / "vtk" / "walls" / f.with_suffix(".vtp").name
            if walls_move and wall_file.exists():
                now = read_outlines(wall_file, dim)
                walls = now if dim == 3 else [o for o, m in zip(now, moving, strict=False) if m]
            renderer.draw(x, body, time, out / "frames" / f.with_suffix(".png").name, walls=walls, colours=colours)
    return out, len(frames)
