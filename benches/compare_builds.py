"""Two builds of the engine in one process, alternated: the honest way to tell a small change from noise.

    python benches/compare_builds.py NEW.so OLD.so [--resolution 256] [--dim 2] [--method naive] [--precision f64]
        [--steps 10] [--rounds 60] [--threads 1] [--warm-up 3] [--scene paper/fluid_incline_noslip] [--ops]

Each argument is a built extension (`python/augmpm/_core.abi3.so` of a checkout, or one unpacked from a
wheel: `maturin build --release`). Both step the same dam break (`augmpm.bench.dam_break_scene`, or
`dam_break_3d_scene` with `--dim 3`; f64 unless `--precision f32`), or the scene file (or shipped scene's
name) of `--scene`, built once each, `--steps` steps a round, in alternating order (A B, B A, …), so that
the machine's drift and the run order fall on both alike. Printed per stage (the engine's stage timers, ns a
particle-step): the median of each build, the median and range of the round-by-round ratio A/B, the ratio of
the fastest rounds (on a shared machine interference mostly slows a round down), and a 95% confidence
interval for the median ratio (`median_interval`; from 6 rounds on): a change whose interval holds 1 is not
told from noise. Whole-process timings include start-up and scene building; this does not.

The scene is built by the installed `augmpm`: both builds must read its scene format. The same file given
twice is one library, loaded once: the two then share an engine module (an A/A run).

With `--ops`, each build is also run under valgrind's callgrind (`augmpm.opcount`, one thread) and its
instructions and floating-point operations per particle-step are printed per stage with their ratio: exact,
where the times are noisy, but fewer instructions need not take less time (see README, Performance). They
are counted over the scene's steps 4–6, whatever `--warm-up` is (valgrind runs ~50× slower): a state near
the start, where the timed rounds may run one long mixed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from math import comb
from pathlib import Path

from augmpm import bench, opcount
from augmpm.scene import SceneError, load_scene
from augmpm.simulation import memory_limit


def median_interval(values: list[float], confidence: float = 0.95) -> tuple[float, float] | None:
    """A distribution-free confidence interval for the median of `values`, taken as independent draws (the
    sign test's): the k-th smallest and the k-th largest, with k the largest for which fewer than k of n
    draws fall below the median with probability at most (1 − confidence)/2, a binomial(n, ½) tail. None
    when no k qualifies (fewer than 6 values at 95%)."""
    n = len(values)
    # Counted in integers (2ⁿ overflows a float from n = 1,024 on; an integer quotient does not).
    tail, k, below = (1.0 - confidence) / 2.0, 0, 0
    for j in range(n + 1):
        below += comb(n, j)
        if below / 2**n > tail:
            break
        k = j + 1
    if k == 0:
        return None
    ordered = sorted(values)
    return ordered[k - 1], ordered[n - k]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("new", type=Path, help="build A: its _core extension")
    parser.add_argument("old", type=Path, help="build B, the yardstick")
    parser.add_argument(
        "--resolution", type=int, help="dam break grid: 128, 256 or 512 (3D: 32, 64, 128); default 256 (3D: 64)"
    )
    parser.add_argument("--dim", type=int, choices=[2, 3], help="the 2D (default) or the 3D dam break")
    parser.add_argument("--method", default="naive", choices=["naive", "augmented"])
    parser.add_argument(
        "--precision", choices=["f64", "f32"], help="the dam break's precision (default f64; a scene file sets its own)"
    )
    parser.add_argument("--steps", type=int, default=10, help="steps a round")
    parser.add_argument("--rounds", type=int, default=60, help="rounds of each build (even: each goes first as often)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--scene", help="a scene file or a shipped scene's name (paper/fluid_incline_noslip) instead of the dam break"
    )
    parser.add_argument(
        "--warm-up", type=int, default=3, help="steps before the rounds (thousands: the particles have mixed)"
    )
    parser.add_argument(
        "--ops",
        action="store_true",
        help="also count each build's instructions and flops per stage under callgrind (needs valgrind, objdump)",
    )
    args = parser.parse_args()
    for path in (args.new, args.old):
        if not path.is_file():
            parser.error(f"{path}: no such extension file")
    if args.rounds < 2 or args.rounds % 2:
        parser.error(f"--rounds {args.rounds}: must be a positive even number (each build goes first as often)")
    if args.warm_up < 0:
        parser.error(f"--warm-up {args.warm_up}: must be at least 0")
    if args.steps < 1:
        parser.error(f"--steps {args.steps}: must be at least 1")
    if args.scene is not None:
        if args.dim is not None or args.resolution is not None or args.precision is not None:
            parser.error(
                "--scene: the scene sets its own grid and precision (--dim, --resolution and --precision are the "
                "dam break's)"
            )
        try:
            scene = load_scene(args.scene).to_json()
        except SceneError as e:
            parser.error(f"--scene: {e}")
        what = args.scene
    else:
        dim = args.dim or 2
        resolution = args.resolution or (256 if dim == 2 else 64)
        dam_break = (bench.dam_break_scene if dim == 2 else bench.dam_break_3d_scene)(resolution)
        scene = dam_break.model_copy(update={"precision": args.precision or "f64"}).to_json()
        # The precision as the scene the builds step holds it.
        what = f"{dim}D dam break at {resolution}, {json.loads(scene)['precision']}"
    if args.ops:
        try:
            opcount.require_tools()
        except opcount.OpCountError as e:
            parser.error(f"--ops: {e}")
    sims = {
        label: opcount.load_extension(label, path).Simulation(scene, args.method, args.threads, memory_limit())
        for label, path in (("A", args.new), ("B", args.old))
    }
    for sim in sims.values():
        sim.step(args.warm_up)
    rounds: dict[str, list[dict[str, float]]] = {"A": [], "B": []}
    for r in range(args.rounds):
        for label in ("A", "B") if r % 2 == 0 else ("B", "A"):
            sim = sims[label]
            before, start = sim.stage_times(), time.perf_counter()
            sim.step(args.steps)
            total = time.perf_counter() - start
            after = sim.stage_times()
            per = sim.num_particles * args.steps / 1e9
            rounds[label].append({"step": total / per, **{k: (after[k] - before[k]) / per for k in after}})
    print(
        f"{what}, {args.method}, {args.threads} thread(s), {args.warm_up} steps, "
        f"then {args.rounds} rounds of {args.steps} steps; ns a particle-step"
    )
    print(f"{'stage':9s} {'A':>7s} {'B':>7s}  {'A/B rounds: median [range]':28s} fastest A/B  median's 95% interval")
    for stage in rounds["A"][0]:
        a = [row[stage] for row in rounds["A"]]
        b = [row[stage] for row in rounds["B"]]
        ratios = [x / y for x, y in zip(a, b, strict=True) if y > 0]
        if not ratios or min(b) <= 0:
            continue
        spread = f"{statistics.median(ratios):.3f} [{min(ratios):.2f}, {max(ratios):.2f}]"
        interval = median_interval(ratios)
        within = "–" if interval is None else f"[{interval[0]:.3f}, {interval[1]:.3f}]"
        print(
            f"{stage:9s} {statistics.median(a):7.1f} {statistics.median(b):7.1f}  {spread:28s} "
            f"{min(a) / min(b):11.3f}  {within}"
        )
    if args.ops:
        try:
            counts = {
                label: opcount.count_scene_ops(scene, args.method, engine=path)
                for label, path in (("A", args.new), ("B", args.old))
            }
        except (opcount.OpCountError, subprocess.CalledProcessError) as e:
            sys.exit(f"--ops: counting failed: {e}")
        print()
        print("\n".join(format_ops(counts["A"], counts["B"])))


def format_ops(a: dict, b: dict) -> list[str]:
    """Per stage, the instructions and flops per particle-step of builds A and B (``opcount.count_scene_ops``)
    and their ratios A/B; stages that ran no instruction in either are left out."""
    lines = [
        f"instructions and flops a particle-step, steps {a['warm_up'] + 1}–{a['warm_up'] + a['steps']} under callgrind",
        f"{'stage':9s} {'A instr':>9s} {'B instr':>9s} {'A/B':>6s} {'A flops':>9s} {'B flops':>9s} {'A/B':>6s}",
    ]
    for stage, x in a["stages"].items():
        y = b["stages"].get(stage)
        if y is None or max(x["instructions"], y["instructions"]) < 0.05:
            continue

        def ratio(p: float, q: float) -> str:
            return f"{p / q:6.3f}" if q > 0 else "     –"

        (i, j), (f, g) = (x["instructions"], y["instructions"]), (x["flops"], y["flops"])
        lines.append(f"{stage:9s} {i:9.1f} {j:9.1f} {ratio(i, j)} {f:9.1f} {g:9.1f} {ratio(f, g)}")
    return lines


if __name__ == "__main__":
    main()
