"""Frames put walls and particles at the pixels their world positions map to, with y pointing up."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from augmpm.render import COLOURS, FrameRenderer, image_size
from augmpm.scene import Scene

WALL_GREY = round(0.85 * 255)  # the shaded wall side, facecolor "0.85"


def _pixel_centre(scene: Scene, col: int, row: int, size_px: int = 640) -> list[float]:
    """World position (m) of the centre of pixel (col, row), row 0 at the top; the domain fills the image."""
    lx, ly = scene.grid.domain
    width, height = image_size(scene, size_px)
    return [(col + 0.5) / width * lx, (height - row - 0.5) / height * ly]


def test_frame_colours_wall_side_grey_and_particle_pixels_by_body(small_scene, tmp_path):
    """The wall side is grey, the fluid side white, and a particle of body b colours its own pixel tab10[b].

    The small scene's polygon wall runs from (0.05, 0.3) to (0.95, 0.05) along the bottom, so (0.5, 0.05) lies
    on the wall side and (0.5, 0.6) inside. A body-1 particle near the bottom must land near the bottom of the
    image (y up) and a dot must not reach 4 px.
    """
    scene = Scene.from_dict(small_scene)
    renderer = FrameRenderer(scene, title="test")
    up, down = _pixel_centre(scene, 200, 100), _pixel_centre(scene, 400, 500)
    x = np.array([up, down])
    path = tmp_path / "frame.png"
    renderer.draw(x, np.array([0, 1]), 0.25, path)
    renderer.close()

    img = np.asarray(Image.open(path).convert("RGB"))
    assert img.shape == (640, 640, 3)
    col, row = (round(v) for v in renderer.to_pixel(np.array([[0.5, 0.05]]))[0])
    assert row > 600  # y = 0.05 m is near the bottom of the image
    np.testing.assert_allclose(img[row, col], [WALL_GREY] * 3, atol=1)
    col, row = (round(v) for v in renderer.to_pixel(np.array([[0.5, 0.6]]))[0])
    assert (img[row, col] == 255).all()
    assert (img[100, 200] == COLOURS[0]).all()
    assert (img[500, 400] == COLOURS[1]).all()
    assert (img[100, 196] == 255).all() and (img[104, 200] == 255).all()


@pytest.mark.parametrize(
    ("domain", "resolution", "height"), [([1.0, 1.0], 16, 640), ([2.0, 1.0], 16, 320), ([1.0, 5 / 12], 12, 272)]
)
def test_frame_height_is_domain_aspect_rounded_to_16_px(small_scene, domain, resolution, height, tmp_path):
    """A frame is size_px wide and as high as the domain's aspect gives, rounded to a multiple of 16 for libx264.

    640 px x 5/12 = 266.7 px rounds to 272 = 17 x 16.
    """
    small_scene["grid"].update(domain=domain, resolution=resolution)
    small_scene["walls"] = []
    small_scene["bodies"][0].update(min=[0.1, 0.1], max=[0.2, 0.2])
    scene = Scene.from_dict(small_scene)
    renderer = FrameRenderer(scene)
    renderer.draw(np.array([[0.15, 0.15]]), np.array([0]), 0.0, tmp_path / "f.png")
    renderer.close()
    assert Image.open(tmp_path / "f.png").size == (640, height)


def test_frame_png_decodes_to_the_drawn_image_in_every_row_band(tmp_path):
    """The PNG draw() writes, re-deflating only the row bands the particles and caption changed, decodes to image().

    Particles spread over the whole height, one row band left untouched between them, so that bands copied
    from the background and bands compressed afresh alternate.
    """
    scene = Scene.from_dict(_circle_wall_scene())
    renderer = FrameRenderer(scene, title="bands")
    rng = np.random.default_rng(1)
    y = np.concatenate([rng.uniform(0.0, 0.45, 200), rng.uniform(0.55, 1.0, 200)])
    x = np.column_stack([rng.uniform(0.0, 1.0, 400), y])
    body = rng.integers(0, 12, 400)
    renderer.draw(x, body, 1.5, tmp_path / "f.png")
    renderer.close()
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "f.png")), renderer.image(x, body, 1.5))


def _circle_wall_scene() -> dict:
    return {
        "name": "bands",
        "grid": {"domain": [1.0, 1.0], "resolution": 16},
        "time": {"dt": 1e-3, "steps": 1, "output_interval": 1},
        "walls": [{"type": "circle", "center": [0.5, 0.5], "radius": 0.3, "side": "outside"}],
        "bodies": [
            {
                "shape": "box",
                "min": [0.1, 0.1],
                "max": [0.2, 0.2],
                "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3},
            }
        ],
    }


@pytest.mark.parametrize("suffix", ["mp4", "gif"])
def test_animation_holds_every_drawn_frame_under_its_own_name(small_scene, suffix, tmp_path):
    """Frames drawn with an animation path all end up in it, and no ``.partial`` file is left after close()."""
    import imageio.v2 as imageio

    scene = Scene.from_dict(small_scene)
    path = tmp_path / f"animation.{suffix}"
    renderer = FrameRenderer(scene, animation=path)
    for i in range(3):
        renderer.draw(np.array([[0.4 + 0.1 * i, 0.6]]), np.array([0]), 0.1 * i, tmp_path / f"f{i}.png")
    assert not path.exists()  # written under the .partial name until close()
    renderer.close()
    assert sorted(p.name for p in tmp_path.glob("animation*")) == [path.name]
    with imageio.get_reader(path) as reader:
        frames = [f for f in reader]
    assert len(frames) == 3
    assert frames[0].shape[:2] == (640, 640)


def test_render_run_redraws_a_moving_run_as_it_was_drawn(tmp_path):
    """`augmpm render RUN_DIR` draws a finished run again from its files alone: with the bodies' colours
    (the default), every frame of a scene whose walls turn equals the run's own PNG except inside the
    legend's box at the top right; the animation is written."""
    import augmpm
    from augmpm.render import render_run
    from augmpm.run import run_scene

    run = tmp_path / "run"
    scene = augmpm.load_scene("moving/turning_box", ["time.output_interval=100"])
    run_scene(scene, run, steps=300, progress=False, animation=None)
    out, frames = render_run(run)
    assert frames == 4 and out == run / "render" and (out / "animation.mp4").stat().st_size > 0
    for k in range(frames):
        before = np.asarray(Image.open(run / "frames" / f"frame_{k:05d}.png").convert("RGB"))
        after = np.asarray(Image.open(out / "frames" / f"frame_{k:05d}.png").convert("RGB"))
        rows, cols = np.nonzero((before != after).any(axis=2))
        assert len(rows) > 0  # the legend
        # The legend: 18 px a body, 8 px from the top and at most 200 px from the right.
        assert rows.max() <= 8 + 18 * len(scene.bodies) and cols.min() > 640 - 200, (rows.max(), cols.min())


def test_render_run_colours_by_a_field_with_a_colour_bar(tmp_path, capsys):
    """Coloured by speed, the frames hold the colour bar (its top rows the top of the colour map); the size is
    as asked.
    A field the frames do not have is bad input (exit 2) naming the option and the fields there are."""
    import augmpm
    from augmpm.cli import main
    from augmpm.render import field_colours
    from augmpm.run import run_scene

    run = tmp_path / "run"
    run_scene(augmpm.load_scene("dam_break", ["grid.resolution=24"]), run, steps=200, progress=False, render=False)
    assert main(["render", str(run), "--colour-by", "speed", "--size", "320", "--fps", "10"]) == 0
    img = np.asarray(Image.open(run / "render" / "frames" / "frame_00005.png").convert("RGB"))
    assert img.shape[1] == 320
    top = field_colours(np.array([1.0]), 0.0, 1.0)[0].astype(int)
    # The bar lies in the top right corner (below the caption): its top rows there, not particles.
    corner = img[40:80, 320 - 120 :].reshape(-1, 3).astype(int)
    near_top = (np.abs(corner - top) <= 12).all(axis=1).sum()
    assert near_top >= 2 * 12  # two of the bar's rows at least (13 px wide inside its outline)
    assert main(["render", str(run), "--colour-by", "pressure"]) == 2
    err = capsys.readouterr().err
    assert "--colour-by" in err and "speed" in err
    assert main(["render", str(tmp_path / "nothing")]) == 2


def test_render_run_draws_a_3d_run(tmp_path):
    """A 3D run is drawn again from its files: every frame, as wide as asked, its particles in the colour
    map's colours (coloured by vy, the field of a falling body)."""
    import augmpm
    from augmpm.render import render_run
    from augmpm.run import run_scene

    run = tmp_path / "run3d"
    scene = augmpm.load_scene("paper3d/fluid_incline_noslip", ["grid.resolution=16", "time.output_interval=20"])
    run_scene(scene, run, steps=40, progress=False, render=False, animation=None)
    out, frames = render_run(run, size_px=256, colour_by="vy", animation="gif")
    assert frames == 3 and (out / "animation.gif").stat().st_size > 0
    img = np.asarray(Image.open(out / "frames" / "frame_00002.png").convert("RGB"))
    assert img.shape[1] == 256
    # Coloured pixels outside the colour bar's box (the walls, box and caption are grey): the particles.
    coloured = np.ptp(img.astype(int), axis=2) > 20
    coloured[:160, 256 - 110 :] = False
    assert coloured.sum() > 50


def test_body_colours_are_matplotlibs_tab10():
    """The particles' body colours, written out in render.py, are matplotlib's tab10 in 8-bit RGB."""
    import matplotlib

    tab10 = np.round(np.array(matplotlib.colormaps["tab10"].colors) * 255).astype(np.uint8)
    assert COLOURS.dtype == np.uint8 and np.array_equal(COLOURS, tab10)


def test_importing_augmpm_does_not_import_matplotlib():
    """`import augmpm` (the run driver and the renderer included) leaves matplotlib unimported: it costs
    ~0.7 s and only draws frame backgrounds, field colours and plots, which import it when they run."""
    import subprocess
    import sys

    code = "import sys, augmpm, augmpm.run, augmpm.render; print(sorted(m for m in sys.modules if 'matplotlib' in m))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
