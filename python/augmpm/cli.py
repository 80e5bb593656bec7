"""The ``augmpm`` command line.

Exit codes: 0 success, 1 a failed run (the simulation went bad), 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from augmpm import _core
from augmpm.files import write_text
from augmpm.run import CHECKPOINT_EVERY, resume_run, run_scene
from augmpm.scene import SCHEMA, SCHEMA3, SHIPPED_SCENES, load_scene, shipped_scenes

EXIT_OK, EXIT_FAILED_RUN, EXIT_BAD_INPUT = 0, 1, 2
_THREADS_HELP = "threads to run on (default: $AUGMPM_THREADS, else every core); results do not depend on it"


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's own exit code is 2 as well
        self.print_usage(sys.stderr)
        print(f"augmpm: error: {message}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="augmpm", description="MLS-MPM simulation with accurate wall boundaries.")
    p.add_argument("--version", action="version", version=f"augmpm {_core.__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("run", help="run a scene file and write its outputs")
    r.add_argument("scene", type=Path, nargs="?", help="scene file (TOML) or a shipped scene's name; not with --resume")
    r.add_argument(
        "--resume",
        type=Path,
        metavar="DIR",
        help="continue the interrupted run in DIR from its checkpoint, with the settings it was started with",
    )
    r.add_argument(
        "--checkpoint-every",
        type=int,
        metavar="K",
        help=f"write a checkpoint every K output frames (default {CHECKPOINT_EVERY}; 0: none)",
    )
    r.add_argument("--out", type=Path, help="output directory (default: runs/<scene name>)")
    r.add_argument("--steps", type=int, help="number of steps (default: the scene's time.steps, or time.end / dt)")
    r.add_argument(
        "--method", choices=["naive", "augmented"], help="wall boundary method (default: the scene's method key)"
    )
    r.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scene value, e.g. --set time.steps=200 --set bodies[0].material.viscosity=10; KEY= removes it",
    )
    r.add_argument("--gif", action="store_true", help="write animation.gif instead of animation.mp4")
    r.add_argument("--no-render", action="store_true", help="skip PNG frames and the animation")
    r.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    r.add_argument("--threads", type=int, metavar="N", help=_THREADS_HELP)

    c = sub.add_parser("compare", help="run a scene with the naive and the augmented walls, side by side")
    c.add_argument("scene", type=Path, help="scene file (TOML)")
    c.add_argument("--out", type=Path, help="output directory (default: runs/<scene name>-compare)")
    c.add_argument("--steps", type=int, help="number of steps (default: the scene's time.steps, or time.end / dt)")
    c.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    c.add_argument("--gif", action="store_true", help="write comparison.gif instead of comparison.mp4")
    c.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    c.add_argument("--threads", type=int, metavar="N", help=_THREADS_HELP)

    b = sub.add_parser("bench", help="measure speed, memory and output cost")
    b.add_argument("--quick", action="store_true", help="fewer steps, dam break at 128² and 256² only (~1 min)")
    b.add_argument("--json", type=Path, metavar="FILE", help="also write the report as JSON")
    b.add_argument(
        "--fig1", type=Path, default=SHIPPED_SCENES / "paper" / "fluid_incline_noslip.toml", help="Fig. 1 scene"
    )
    b.add_argument("--threads", type=int, metavar="N", help="threads of the multi-threaded rows (default: every core)")
    b.add_argument(
        "--peers",
        type=Path,
        metavar="DIR",
        help="also run the peer engines of DIR/run.sh (mpm88 in Taichi and Rust) alongside the 2D dam break",
    )
    b.add_argument(
        "--ops",
        action="store_true",
        help="also count each stage's instructions and floating-point operations per particle-step under "
        + "valgrind's callgrind (needs valgrind and objdump; ~2–3 minutes more)",
    )

    w = sub.add_parser("sweep", help="run a scene over a grid and/or random samples of its keys, on Dask")
    w.add_argument("spec", type=Path, help="sweep spec (TOML): the base scene and what to vary")
    w.add_argument("--out", type=Path, help="output directory (default: runs/<spec name>)")
    w.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler (tcp://host:port); default: a local cluster started for the sweep",
    )
    w.add_argument("--workers", type=int, metavar="N", help="workers of the local cluster (default: one per core)")
    w.add_argument("--no-progress", action="store_true", help="hide the progress bar")

    d = sub.add_parser("dataset", help="generate a training set for learned simulators (GNS format), on Dask")
    d.add_argument("spec", type=Path, help="dataset spec (TOML): trajectories, materials, resolution, seed")
    d.add_argument("--out", type=Path, help="output directory (default: runs/<spec name>)")
    d.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler (default: a local cluster)")
    d.add_argument("--workers", type=int, metavar="N", help="workers of the local cluster (default: one per core)")
    d.add_argument("--no-progress", action="store_true", help="hide the progress bar")

    rr = sub.add_parser("render", help="draw a finished run's frames and animation again, without running it")
    rr.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run directory (augmpm run's output)")
    rr.add_argument("--out", type=Path, help="output directory (default: RUN_DIR/render)")
    rr.add_argument("--size", type=int, default=640, metavar="PX", help="frame width in pixels (default 640)")
    rr.add_argument("--fps", type=int, default=20, help="animation frames per second (default 20)")
    rr.add_argument(
        "--colour-by",
        default="body",
        metavar="FIELD",
        help="body (default, with a legend), speed, vx, vy, vz (3D) or a per-particle array of the frames "
        "(with a colour bar)",
    )
    rr.add_argument("--gif", action="store_true", help="write animation.gif instead of animation.mp4")

    v = sub.add_parser("validate", help="run the validation suite (analytic flows, experiments) and write a report")
    v.add_argument("--quick", action="store_true", help="coarse and short (a few minutes on 2 cores)")
    v.add_argument("--out", type=Path, default=Path("runs/validation"), help="output directory")
    v.add_argument("--no-progress", action="store_true", help="do not print progress")
    v.add_argument(
        "--jobs", type=int, metavar="N", help="cases run at once, each in a process of its own (default: one per core)"
    )

    sub.add_parser("scenes", help="list the scenes shipped with augmpm (run one by its name)")
    sc = sub.add_parser("schema", help="print the JSON Schema of scene files (for editors), or the scene reference")
    sc.add_argument("--markdown", action="store_true", help="the scene reference as Markdown, as in the README")
    sc.add_argument("--3d", dest="three_d", action="store_true", help="the JSON Schema of 3D scene files")

    i = sub.add_parser("interp-test", help="the paper's Fig. 4 interpolation test (naive vs augmented)")
    i.add_argument("--out", type=Path, default=Path("runs/interp-test"), help="output directory")
    i.add_argument("--resolution", type=int, default=30, help="cells per side (default 30, as in the paper)")
    return p


def _output_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise _core.SceneError(f"--out: {path} exists and is not a directory")
    return path


def _run(args: argparse.Namespace) -> int:
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        raise _core.SceneError(f"--checkpoint-every: must be non-negative, got {args.checkpoint_every}")
    if args.resume is not None:
        given = [
            flag
            for flag, value in [
                ("SCENE", args.scene),
                ("--out", args.out),
                ("--steps", args.steps),
                ("--method", args.method),
                ("--set", args.overrides),
                ("--gif", args.gif),
                ("--no-render", args.no_render),
            ]
            if value not in (None, False, [])
        ]
        if given:
            raise _core.SceneError(
                f"--resume: continues the run as it was started; {', '.join(given)} cannot be given with it"
            )
        out = args.resume
        result = resume_run(
            out,
            progress=not args.no_progress,
            threads=args.threads,
            checkpoint_every=args.checkpoint_every,
            raise_on_failure=False,
        )
    else:
        if args.scene is None:
            raise _core.SceneError("SCENE: give a scene file, or --resume DIR")
        if args.steps is not None and args.steps < 0:
            raise _core.SceneError(f"--steps: must be non-negative, got {args.steps}")
        scene = load_scene(args.scene, args.overrides)
        out = _output_dir(args.out or Path("runs") / (scene.name or args.scene.stem))
        result = run_scene(
            scene,
            out,
            method=args.method,
            steps=args.steps,
            progress=not args.no_progress,
            animation=None if args.no_render else ("gif" if args.gif else "mp4"),
            render=not args.no_render,
            threads=args.threads,
            checkpoint_every=CHECKPOINT_EVERY if args.checkpoint_every is None else args.checkpoint_every,
            raise_on_failure=False,
        )
    for w in result.warnings:
        print(f"augmpm: warning: {w}", file=sys.stderr)
    m = result.final_metrics
    if result.error:
        print(f"augmpm: run failed: {result.error}", file=sys.stderr)
        print(f"augmpm: kept {result.frames} frames in {out}", file=sys.stderr)
        return EXIT_FAILED_RUN
    print(
        f"{result.frames} frames in {out} ({result.wall_time:.1f} s); step {m['step']}, t = {m['time']:.4g} s, "
        f"kinetic energy {m['kinetic_energy']:.4g}, {m['n_outside']} particle{'' if m['n_outside'] == 1 else 's'} "
        f"outside the walls, deepest {m['max_penetration']:.2g} h"
    )
    return EXIT_OK


def _compare(args: argparse.Namespace) -> int:
    from augmpm.compare import compare_scene

    if args.steps is not None and args.steps < 0:
        raise _core.SceneError(f"--steps: must be non-negative, got {args.steps}")
    scene = load_scene(args.scene, args.overrides)
    out = _output_dir(args.out or Path("runs") / f"{scene.name or args.scene.stem}-compare")
    result = compare_scene(
        scene,
        out,
        steps=args.steps,
        progress=not args.no_progress,
        animation="gif" if args.gif else "mp4",
        threads=args.threads,
    )
    print(result.table())
    ext = "gif" if args.gif else "mp4"
    animation = f", comparison.{ext}" if (out / f"comparison.{ext}").exists() else ""
    print(f"written to {out}: naive/, augmented/, comparison.csv, comparison.png{animation}")
    failed = [m for m, r in result.runs.items() if r.error]
    for m in failed:
        print(f"augmpm: {m} run failed: {result.runs[m].error}", file=sys.stderr)
    return EXIT_FAILED_RUN if failed else EXIT_OK


def _validate(args: argparse.Namespace) -> int:
    from augmpm.simulation import available_cores
    from augmpm.validation.suite import all_augmented_pass, run_validation

    jobs = args.jobs if args.jobs is not None else available_cores()
    if jobs < 1:
        raise _core.SceneError(f"--jobs: must be at least 1, got {jobs}")
    out = _output_dir(args.out)
    records = run_validation(out, quick=args.quick, progress=not args.no_progress, jobs=jobs)
    judged = [r for r in records if r.method == "augmented" and r.passed is not None]
    failed = [r for r in judged if not r.passed]
    print(f"augmented: {len(judged) - len(failed)} of {len(judged)} judged metrics pass; report in {out / 'report.md'}")
    for r in failed:
        print(f"  not met: {r.case} {r.angle_deg:g}° {r.metric} = {r.value:.4g} (tolerance {r.tolerance:g})")
    return EXIT_OK if all_augmented_pass(records) else EXIT_FAILED_RUN


def _on_dask(args: argparse.Namespace, load_spec, make, format_summary):
    """Reads SPEC, runs ``make`` (a sweep or a dataset) on Dask into ``--out`` and prints its summary."""
    if args.workers is not None and args.scheduler is not None:
        raise _core.SceneError("--workers: sizes the local cluster; not with --scheduler")
    spec = load_spec(args.spec)
    out = _output_dir(args.out or Path("runs") / args.spec.stem)
    result = make(spec, out, scheduler=args.scheduler, workers=args.workers, progress=not args.no_progress)
    print(format_summary(result))
    return result


def _sweep(args: argparse.Namespace) -> int:
    from augmpm import sweep

    result = _on_dask(args, sweep.load_spec, sweep.run_sweep, sweep.format_summary)
    return EXIT_FAILED_RUN if result.counts()["error"] else EXIT_OK


def _dataset(args: argparse.Namespace) -> int:
    from augmpm import dataset

    _on_dask(args, dataset.load_spec, dataset.make_dataset, dataset.format_summary)
    return EXIT_OK


def _render(args: argparse.Namespace) -> int:
    from augmpm.render import render_run

    out, frames = render_run(
        args.run_dir,
        args.out,
        size_px=args.size,
        fps=args.fps,
        colour_by=args.colour_by,
        animation="gif" if args.gif else "mp4",
    )
    print(f"{frames} frames drawn into {out}: frames/, animation.{'gif' if args.gif else 'mp4'}")
    return EXIT_OK


def _bench(args: argparse.Namespace) -> int:
    import subprocess

    from augmpm.bench import PeerError, format_report, run_bench
    from augmpm.opcount import OpCountError

    try:
        report = run_bench(
            quick=args.quick,
            fig1=args.fig1,
            threads=args.threads,
            log=lambda s: print(s, file=sys.stderr),
            peers=args.peers,
            ops=args.ops,
        )
    except (_core.SimulationError, subprocess.CalledProcessError, PeerError, OpCountError) as e:
        detail = getattr(e, "stderr", None) or ""
        print(f"augmpm: benchmark failed: {e}\n{detail}".rstrip(), file=sys.stderr)
        return EXIT_FAILED_RUN
    print(format_report(report))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_text(args.json, json.dumps(report, indent=2))
        print(f"report written to {args.json}")
    return EXIT_OK


def _interp_test(args: argparse.Namespace) -> int:
    from augmpm.interp import interpolation_test

    if not 16 <= args.resolution <= 1024:
        raise _core.SceneError(f"--resolution: must lie in [16, 1024], got {args.resolution}")
    for r in interpolation_test(_output_dir(args.out), resolution=args.resolution):
        print(
            f"{r.method:>9}: within 2h of the wall, away from corners: "
            f"max {r.max_error:.3g} h, RMS {r.rms_error:.3g} h; "
            f"with corners: max {r.max_error_with_corners:.3g} h, RMS {r.rms_error_with_corners:.3g} h"
        )
    print(f"written to {args.out}: interp_test.png, interp_test.json")
    return EXIT_OK


def _scenes() -> int:
    """Prints each shipped scene's name and the first line of its description (its leading comment)."""
    for name, path in shipped_scenes().items():
        lines = path.read_text(encoding="utf-8").splitlines()
        about = next((line.lstrip("# ").strip() for line in lines if line.startswith("#")), "")
        print(f"{name:<32} {about}")
    return 0


def _schema(markdown: bool, three_d: bool = False) -> int:
    """Prints the JSON Schema of scene files, 2D or (``three_d``) 3D (TOML editors such as Taplo validate
    against it), or the scene reference generated from both."""
    if three_d and not markdown:
        print(json.dumps(SCHEMA3, indent=2, ensure_ascii=False))
    elif markdown:
        from augmpm.reference import scene_reference

        print(scene_reference(), end="")
    else:
        print(json.dumps(SCHEMA, indent=2, ensure_ascii=False))
    return 0


def main(argv: list[str] | None = None) -> int:
    try:
        args = _parser().parse_args(argv)
    except SystemExit as e:  # --help, --version, or a usage error (code 2)
        return int(e.code or 0)
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "interp-test":
            return _interp_test(args)
        if args.command == "validate":
            return _validate(args)
        if args.command == "bench":
            return _bench(args)
        if args.command == "sweep":
            return _sweep(args)
        if args.command == "dataset":
            return _dataset(args)
        if args.command == "render":
            return _render(args)
        if args.command == "scenes":
            return _scenes()
        if args.command == "schema":
            return _schema(args.markdown, args.three_d)
    except _core.SceneError as e:
        print(f"augmpm: bad input: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except _core.Error as e:  # SimulationError outside a run, or an internal error
        print(f"augmpm: {e}", file=sys.stderr)
        return EXIT_FAILED_RUN
    except OSError as e:
        print(f"augmpm: cannot write output: {e}", file=sys.stderr)
        return EXIT_FAILED_RUN
    except KeyboardInterrupt:
        print(
            "augmpm: interrupted; frames written so far are kept (augmpm run --resume DIR continues a run)",
            file=sys.stderr,
        )
        return 130
    return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
