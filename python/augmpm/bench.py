"""``augmpm bench``: the engine's speed, memory and output cost, measured.

Cases (issue 5):

- the paper's Fig. 1 scene (viscous fluid on a no-slip incline), naive and augmented, timed over
  10,000 steps (``--quick``: 2,000, scaled to 10,000) and compared with the authors' code
  (9.3 s naive, 32.3 s augmented, one thread of this machine kind; ``spec/paper-scenes.md``);
- a fluid dam break in a tank tilted 20° to the grid (so that many particles sit next to
  inclined walls) at three sizes, ~8k particles on 128², ~65k on 256², ~530k on 512²: f64 and
  f32, naive and augmented, on 1 and on 2 threads: particle-steps per second, the augmented/naive
  cost ratio, the 2-thread speed-up, peak memory per particle, and the time split per stage;
- thread scaling (issue 16), with more than one thread: the 256² and 512² naive f64 dam break, well
  under way, on one thread, on N, and as N one-thread runs at once, alternated round by round: the speed-up
  over one thread against the machine's own ceiling at that moment (what N runs that share nothing get), per
  stage too;
- a 3D fluid dam break in a box tank turned 20° about an axis in no coordinate plane, ~20k particles
  on 32³, ~160k on 64³ and ~1M on 128³: f64 and f32, naive and augmented, on the chosen threads;
- the cost of output: a paper-scene run with every output (frames, images, animation) against the
  same run without;
- the cost of coupling rigid bodies (issue 15): ``rigid/floating_bodies`` from its state at 1 s, with its
  bodies free against the same state with each body replaced by a wall held where the body is (a wall
  that may move but stands still, and a still wall);
- with ``--peers DIR`` (issue 16), the peer engines of ``DIR/run.sh`` (mpm88, Hu et al. 2018's 88-line
  MLS-MPM fluid in float32, in Taichi and in Rust + rayon) on the same machine and thread count, at the
  dam break's particle counts (65,536 on 256², 524,288 on 512²), alternated round by round with augmpm's
  naive f32 and f64 and augmented f64 dam break: the ratio of particle-steps per second to the faster peer.

Configurations compared with each other run interleaved in one process (A B A B …), because this
machine's speed drifts by up to 2× over an hour; memory is measured in a fresh process per
configuration (peak resident set size over that of a process that only imported augmpm).
"""

from __future__ import annotations

import functools
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

from augmpm.scene import SHIPPED_SCENES, Scene, Scene3, load_scene, scene_path
from augmpm.simulation import Simulation

#: The authors' code on this machine kind, Fig. 1 scene, 10,000 steps, one thread (s).
AUTHORS_FIG1_SECONDS = {"naive": 9.3, "augmented": 32.3}
#: Fig. 1 steps of the paper's comparison.
FIG1_STEPS = 10_000
DEFAULT_FIG1 = SHIPPED_SCENES / "paper" / "fluid_incline_noslip.toml"
#: Dam-break sizes: grid resolution → (particles per cell, part of the tank's width filled).
DAM_BREAK_SIZES = {128: (4, 0.22), 256: (4, 0.44), 512: (8, 0.44)}
#: 3D dam-break sizes: grid resolution → particles per cell.
DAM_BREAK_3D_SIZES = {32: 8, 64: 8, 128: 6}
METHODS = ("naive", "augmented")
PRECISIONS = ("f64", "f32")
STAGES = ("sort", "density", "boundary", "p2g", "grid", "g2p")


def dam_break_scene(resolution: int) -> Scene:
    """A water column against the lower-left wall of a square tank rotated 20° about the domain
    centre; gravity −9.81 m/s², CFL 0.5 time step."""
    per_cell, fill = DAM_BREAK_SIZES[resolution]
    angle = math.radians(20.0)
    cos, sin = math.cos(angle), math.sin(angle)
    side = 0.97 / (cos + sin)  # the rotated tank fits in the unit domain with a 1.5% margin
    margin = 0.75 / resolution  # keep seeded particles 3/4 of a cell off the walls

    def place(u: float, v: float) -> list[float]:
        return [0.5 + cos * u - sin * v, 0.5 + sin * u + cos * v]

    half = side / 2
    tank = [place(-half, -half), place(half, -half), place(half, half), place(-half, half)]
    u0, u1 = -half + margin, -half + fill * side
    v0, v1 = -half + margin, half - margin
    water = [place(u0, v0), place(u1, v0), place(u1, v1), place(u0, v1)]
    return Scene.from_dict(
        {
            "name": f"bench_dam_break_{resolution}",
            "seed": 1,
            "gravity": [0.0, -9.81],
            "wall_condition": "slip",
            "grid": {"domain": [1.0, 1.0], "resolution": resolution},
            "time": {"cfl": 0.5, "steps": 100, "output_interval": 100},
            "walls": [{"type": "polygon", "vertices": tank}],
            "bodies": [
                {
                    "shape": "polygon",
                    "vertices": water,
                    "seeding": {"per_cell": per_cell},
                    "material": _BENCH_FLUID,
                }
            ],
        }
    )


#: The 3D dam break's fluid: that of the 2D one.
_BENCH_FLUID = {
    "type": "fluid",
    "density": 1000.0,
    "stiffness": 2.0e4,
    "gamma": 7.0,
    "viscosity": 0.5,
    "min_pressure": 0.0,
}


def dam_break_3d_scene(resolution: int) -> Scene3:
    """A water column against one side of a cubic tank (edge 0.8 m) turned 20° about (1, 0.2, 0.6) in the
    unit domain: the part of the box [0, 0.35] × [0, 0.5] × [0, 1] m inside the tank; gravity −9.81 m/s²
    along y, CFL 0.5 time step, slip walls."""
    axis = [1.0, 0.2, 0.6]
    return Scene3.from_dict(
        {
            "name": f"bench_dam_break_3d_{resolution}",
            "seed": 1,
            "gravity": [0.0, -9.81, 0.0],
            "wall_condition": "slip",
            "grid": {"domain": [1.0, 1.0, 1.0], "resolution": resolution},
            "time": {"cfl": 0.5, "steps": 100, "output_interval": 100},
            "walls": [
                {"type": "box", "center": [0.5] * 3, "size": [0.8] * 3, "axis": axis, "angle": math.radians(20.0)}
            ],
            "bodies": [
                {
                    "shape": "box",
                    "min": [0.0, 0.0, 0.0],
                    "max": [0.35, 0.5, 1.0],
                    "fill": True,
                    "seeding": {"per_cell": DAM_BREAK_3D_SIZES[resolution]},
                    "material": _BENCH_FLUID,
                }
            ],
        }
    )


def interleaved(sims: dict[str, Simulation], steps: int, rounds: int) -> dict[str, dict]:
    """Advances every simulation by ``steps`` in ``rounds`` alternating chunks; per simulation the
    wall time (s), particle-steps per second and seconds per stage. A simulation that fails is
    dropped from later rounds and reported with its ``error``."""
    from augmpm import _core

    chunk = max(1, steps // rounds)
    wall = dict.fromkeys(sims, 0.0)
    done_steps = dict.fromkeys(sims, 0)
    errors: dict[str, str] = {}
    before = {k: s.stage_times() for k, s in sims.items()}
    done = 0
    while done < steps:
        n = min(chunk, steps - done)
        for k, sim in sims.items():
            if k in errors:
                continue
            t = time.perf_counter()
            try:
                sim.step(n)
                done_steps[k] += n
            except _core.SimulationError as e:
                errors[k] = str(e)
            wall[k] += time.perf_counter() - t
        done += n
    out = {}
    for k, sim in sims.items():
        after = sim.stage_times()
        out[k] = {
            "seconds": wall[k],
            "steps": done_steps[k],
            "particles": sim.num_particles,
            "particle_steps_per_s": sim.num_particles * done_steps[k] / wall[k] if k not in errors else math.nan,
            "stages_s": {s: after[s] - before[k][s] for s in STAGES},
        }
        if k in errors:
            out[k]["error"] = errors[k]
    return out


def bench_fig1(path: Path, steps: int, threads: int) -> list[dict]:
    """Fig. 1, both methods interleaved; wall time scaled to the paper's 10,000 steps."""
    scene = load_scene(path)
    sims = {m: Simulation(scene, m, threads=threads) for m in METHODS}
    result = interleaved(sims, steps, rounds=4)
    rows = []
    for m in METHODS:
        r = result[m]
        # A failed run has no time for the whole run.
        seconds = r["seconds"] * FIG1_STEPS / steps if "error" not in r else math.nan
        rows.append(
            {
                "case": "fig1",
                "method": m,
                "threads": threads,
                **r,
                "seconds_10k_steps": seconds,
                "speedup_vs_authors": AUTHORS_FIG1_SECONDS[m] / seconds,
            }
        )
    return rows


def bench_dam_break(resolution: int, steps: int, threads: tuple[int, ...], dim: int = 2) -> list[dict]:
    """One size of the 2D (``dim`` 2) or 3D dam break: every precision × method × thread count interleaved,
    after 3 warm-up steps each."""
    configs = [(p, m, t) for p in PRECISIONS for m in METHODS for t in threads]
    sims = {}
    for p, m, t in configs:
        scene = _dam_break(resolution, dim).model_copy(update={"precision": p})
        sims[f"{p}/{m}/{t}"] = Simulation(scene, m, threads=t)
        sims[f"{p}/{m}/{t}"].step(3)
    result = interleaved(sims, steps, rounds=4)
    rows = []
    case = f"dam_break_{resolution}" if dim == 2 else f"dam_break_3d_{resolution}"
    for p, m, t in configs:
        r = result[f"{p}/{m}/{t}"]
        row = {"case": case, "dim": dim, "method": m, "threads": t, "precision": p, **r}
        naive, one = result[f"{p}/naive/{t}"], result[f"{p}/{m}/1"] if 1 in threads else None
        row["augmented_over_naive"] = naive["particle_steps_per_s"] / r["particle_steps_per_s"]
        if one is not None:
            row["speedup_over_1_thread"] = r["particle_steps_per_s"] / one["particle_steps_per_s"]
        if (dim, resolution, p, m, t) == (3, TARGET_3D_RESOLUTION, "f32", "naive", TARGET_3D_THREADS):
            row["target_particle_steps_per_s"] = TARGET_3D_RATE
        row["memory"] = _memory_in_subprocess(resolution, m, p, dim)
        rows.append(row)
    return rows


def _dam_break(resolution: int, dim: int) -> Scene | Scene3:
    return dam_break_scene(resolution) if dim == 2 else dam_break_3d_scene(resolution)


#: Issue 16's target for the step's speed-up on two threads over one, at 256² and above.
SCALING_TARGET = 1.85
#: Rounds of the thread-scaling case (even: the order is reversed every other round, so that each configuration
#: runs as often before as after each other one).
SCALING_ROUNDS = 12


def bench_scaling(resolution: int, steps: int, threads: int, warm_up: int, rounds: int = SCALING_ROUNDS) -> dict:
    """The naive f64 2D dam break at ``resolution`` on one thread, on ``threads`` threads, and as ``threads``
    one-thread simulations stepped at once (each from a thread of this process; a step runs without the
    interpreter's lock): the last is what the machine gives work that shares nothing at that moment, the
    ceiling of the speed-up. Each round steps each of the three configurations ``steps`` steps, in turn, in the
    reverse order every other round, after ``warm_up`` steps each (the particles mixed as in a long run). The
    speed-up and the ceiling are the medians of the rounds' ratios; per stage, the ratio of the stage's summed
    times."""
    import threading

    if rounds < 2 or rounds % 2:
        raise ValueError(f"rounds: must be a positive even number (the order is reversed every other), got {rounds}")
    scene = dam_break_scene(resolution)
    one, many = Simulation(scene, "naive", threads=1), Simulation(scene, "naive", threads=threads)
    apart = [Simulation(scene, "naive", threads=1) for _ in range(threads)]
    for sim in (one, many, *apart):
        sim.step(warm_up)

    def at_once() -> None:
        workers = [threading.Thread(target=sim.step, args=(steps,)) for sim in apart]
        for w in workers:
            w.start()
        for w in workers:
            w.join()

    runs = {"one": lambda: one.step(steps), "many": lambda: many.step(steps), "apart": at_once}
    seconds: dict[str, list[float]] = {k: [] for k in runs}
    before = {"one": one.stage_times(), "many": many.stage_times()}
    for r in range(rounds):
        for k in runs if r % 2 == 0 else reversed(runs):
            t = time.perf_counter()
            runs[k]()
            seconds[k].append(time.perf_counter() - t)
    if any(sim.steps_done != warm_up + rounds * steps for sim in (one, many, *apart)):
        raise RuntimeError("a simulation of the thread-scaling case did not take every step")
    speedups = [a / b for a, b in zip(seconds["one"], seconds["many"], strict=True)]
    ceilings = [threads * a / b for a, b in zip(seconds["one"], seconds["apart"], strict=True)]
    after = {"one": one.stage_times(), "many": many.stage_times()}
    stage = {k: {s: after[k][s] - before[k][s] for s in STAGES} for k in after}
    return {
        "case": f"scaling_{resolution}",
        "method": "naive",
        "precision": "f64",
        "threads": threads,
        "particles": one.num_particles,
        "steps": steps,
        "rounds": rounds,
        "warm_up": warm_up,
        "speedup_rounds": speedups,
        "ceiling_rounds": ceilings,
        "speedup": statistics.median(speedups),
        "ceiling": statistics.median(ceilings),
        "stage_speedups": {
            s: stage["one"][s] / stage["many"][s] for s in STAGES if stage["many"][s] > 0 and stage["one"][s] > 0
        },
    }


#: Peer sizes (``run.sh``'s names) at the dam break's resolutions: 8,192 / 65,536 / 524,288 particles.
PEER_SIZES = {128: "S", 256: "M", 512: "L"}
#: Issue 16's targets against the faster peer (particle-steps per second, same machine, 2 threads).
PEER_TARGETS = {("f32", "naive"): 1.2, ("f64", "naive"): 0.9}
#: Longest a run of the peers' script may take (s): its first run builds them (a venv with Taichi, a Rust binary).
PEER_TIMEOUT = 1800
#: ... and of the augmented step's cost over the naive one's (f64).
AUGMENTED_OVER_NAIVE_TARGET = 1.15


def bench_peers(peers: Path, resolution: int, steps: int, threads: int, rounds: int = 3, log=print) -> list[dict]:
    """augmpm's 2D dam break at ``resolution`` (naive f32 and f64, augmented f64, on ``threads``) against
    the peer engines of ``peers/run.sh``, alternating: each round steps every augmpm configuration
    ``steps`` times (interleaved) and then runs the peers (each reports the median of its own 3 timed runs
    of ``steps`` steps). Per configuration, the median over the rounds of particle-steps per second and
    its ratio to the faster peer's median; a missing script or a peer run that fails raises
    ``PeerError``."""
    script = Path(peers) / "run.sh"
    if not script.is_file():
        raise PeerError(f"--peers: {script} not found (the folder of the peer engines' run.sh)")
    if resolution not in PEER_SIZES:
        raise PeerError(f"--peers: no peer size for the {resolution}² dam break (sizes {sorted(PEER_SIZES)})")
    configs = [("f32", "naive"), ("f64", "naive"), ("f64", "augmented")]
    sims = {}
    for p, m in configs:
        scene = dam_break_scene(resolution).model_copy(update={"precision": p})
        sims[f"{p}/{m}"] = Simulation(scene, m, threads=threads)
        sims[f"{p}/{m}"].step(3)
    ours: dict[str, list[float]] = {k: [] for k in sims}
    theirs: dict[str, list[float]] = {}
    peer_particles: dict[str, int] = {}
    for r in range(rounds):
        result = interleaved(sims, steps, rounds=1)
        for k, row in result.items():
            if "error" in row:
                raise PeerError(f"the {resolution}² dam break, {k}, failed: {row['error']}")
            ours[k].append(row["particle_steps_per_s"])
        log(f"  round {r + 1}/{rounds}: peers {PEER_SIZES[resolution]} on {threads} threads …")
        found = _run_peers(script, PEER_SIZES[resolution], threads, steps)
        if not found:
            raise PeerError(f"{script} printed no RESULT line (round {r + 1})")
        for impl, row in found.items():
            theirs.setdefault(impl, []).append(row["pss_median"])
            peer_particles[impl] = row["n"]
    peer = {impl: statistics.median(v) for impl, v in theirs.items()}
    faster = max(peer, key=peer.get)
    rows = []
    naive64 = statistics.median(ours["f64/naive"])
    for p, m in configs:
        pss = statistics.median(ours[f"{p}/{m}"])
        row = {
            "case": f"peers_{resolution}",
            "method": m,
            "precision": p,
            "threads": threads,
            "rounds": rounds,
            "steps": steps,
            "particles": sims[f"{p}/{m}"].num_particles,
            "particle_steps_per_s": pss,
            "rounds_particle_steps_per_s": ours[f"{p}/{m}"],
            "peers": peer,
            "peers_rounds": theirs,
            "peer_particles": peer_particles,
            "faster_peer": faster,
            "over_faster_peer": pss / peer[faster],
            "target_over_faster_peer": PEER_TARGETS.get((p, m)),
        }
        if m == "augmented":
            row["augmented_over_naive"] = naive64 / pss
            row["target_augmented_over_naive"] = AUGMENTED_OVER_NAIVE_TARGET
        rows.append(row)
    return rows


class PeerError(RuntimeError):
    """The peer engines could not be run or read."""


def _run_peers(script: Path, size: str, threads: int, steps: int) -> dict[str, dict]:
    """One run of the peers' script at ``size``: its ``RESULT {json}`` lines by engine."""
    try:
        out = subprocess.run(
            ["bash", str(script), size, str(threads), str(steps)],
            capture_output=True,
            text=True,
            check=True,
            timeout=PEER_TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        raise PeerError(f"{script} {size} {threads} {steps} ran past {PEER_TIMEOUT} s") from None
    except subprocess.CalledProcessError as e:
        tail = "\n".join((e.stderr or "").strip().splitlines()[-5:])
        raise PeerError(f"{script} {size} {threads} {steps} exited with {e.returncode}: {tail}") from None
    results = {}
    for line in out.stdout.splitlines():
        if line.startswith("RESULT "):
            try:
                row = json.loads(line.removeprefix("RESULT "))
                results[str(row["impl"])] = {"pss_median": float(row["pss_median"]), "n": int(row["n"])}
            except (ValueError, KeyError, TypeError) as e:
                raise PeerError(f"{script}: unreadable RESULT line {line[:120]!r} ({e})") from None
    return results


#: Shipped scenes whose walls move, timed against themselves with the walls held still.
MOVING_SCENES = ("moving/shaken_tank", "moving/stirred_tank")


def bench_moving(steps: int, threads: int) -> list[dict]:
    """The cost of moving walls: each scene of :data:`MOVING_SCENES` with its walls moving and the same
    scene with every ``motion`` removed, both methods, interleaved; the ratio of their step times."""
    rows = []
    for name in MOVING_SCENES:
        moving = load_scene(name)
        still = moving.model_copy(deep=True)
        for wall in still.walls:
            wall.motion = None
        sims = {}
        for m in METHODS:
            for label, scene in (("moving", moving), ("still", still)):
                sims[f"{m}/{label}"] = Simulation(scene, m, threads=threads)
                sims[f"{m}/{label}"].step(3)
        result = interleaved(sims, steps, rounds=4)
        for m in METHODS:
            r, base = result[f"{m}/moving"], result[f"{m}/still"]
            ratio = (
                (r["seconds"] / r["steps"]) / (base["seconds"] / base["steps"])
                if r["steps"] and base["steps"]
                else math.nan
            )
            rows.append(
                {
                    "case": f"moving_{name.split('/')[-1]}",
                    "method": m,
                    "threads": threads,
                    **r,
                    "still_seconds": base["seconds"],
                    "moving_over_still": ratio,
                }
            )
    return rows


def _memory_in_subprocess(resolution: int, method: str, precision: str = "f64", dim: int = 2) -> dict:
    """Peak memory of building and stepping one dam break, in a fresh process."""
    base = _baseline()
    run = _worker(["memory", str(resolution), method, precision, str(dim)])
    peak = run["max_rss"] - base["max_rss"]
    n = run["particles"]
    return {
        "peak_bytes": peak,
        "peak_bytes_per_particle": peak / n,
        "accounted": run["accounted"],
        "per_particle_without_grid": (run["accounted"]["particles"] + run["accounted"]["particle_scratch"]) / n,
    }


@functools.cache
def _baseline() -> dict:
    """Peak memory of a fresh process that only imported augmpm (measured once)."""
    return _worker(["baseline"])


def _worker(args: list[str]) -> dict:
    out = subprocess.run(
        [sys.executable, "-m", "augmpm.bench", *args], capture_output=True, text=True, check=True, env=os.environ
    )
    return json.loads(out.stdout)


def _max_rss_bytes() -> int:
    """Peak resident set of this process (bytes). Linux's ``ru_maxrss`` survives ``exec`` and so
    starts at the parent's size; ``VmHWM`` belongs to this process's own address space."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


#: Rounds of the output cost, each a run with every output and one without (even: each goes first as often).
OUTPUT_ROUNDS = 4
#: Issue 16's 3D target: the ~1M-particle fluid (the 128³ dam break), naive walls, f32, on 2 threads, in particle-steps
#: per second.
TARGET_3D_RESOLUTION, TARGET_3D_THREADS, TARGET_3D_RATE = 128, 2, 8e6

#: Issue 16's target for the output's share of a paper scene's run at its default interval.
OUTPUT_TARGET = 0.10


def bench_output(path: Path, steps: int, threads: int, rounds: int = OUTPUT_ROUNDS) -> list[dict]:
    """A paper-scene run with every output against the same run without rendering or files, alternated
    ``rounds`` times per method (first one, then the other, the order swapped each round): the share is the
    median of the rounds' shares, so that the machine's drift between two runs does not count as output. Both
    runs are timed from the simulation's construction (``run_scene`` builds its own), after one untimed short
    run with output (imports, the renderer's first frame, ffmpeg's start)."""
    from augmpm.run import run_scene

    if rounds < 2 or rounds % 2:
        raise ValueError(f"rounds: must be a positive even number (each run goes first as often), got {rounds}")
    scene = load_scene(path)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        run_scene(scene, Path(tmp) / "warm-up", steps=min(steps, 2 * scene.time.output_interval), progress=False)
    for m in METHODS:
        bare, full = [], []
        for k in range(rounds):
            with tempfile.TemporaryDirectory() as tmp:
                for with_output in (False, True) if k % 2 == 0 else (True, False):
                    t = time.perf_counter()
                    if with_output:
                        run_scene(scene, Path(tmp) / "run", method=m, steps=steps, progress=False, threads=threads)
                        full.append(time.perf_counter() - t)
                    else:
                        Simulation(scene, m, threads=threads).step(steps)
                        bare.append(time.perf_counter() - t)
        shares = [max(0.0, f - b) / f for b, f in zip(bare, full, strict=True)]
        rows.append(
            {
                "case": "output",
                "method": m,
                "threads": threads,
                "steps": steps,
                "frames": steps // scene.time.output_interval + 1,
                "rounds": rounds,
                "simulation_s": statistics.median(bare),
                "run_with_output_s": statistics.median(full),
                "output_fraction": statistics.median(shares),
                "output_fraction_range": [min(shares), max(shares)],
            }
        )
    return rows


#: The shipped scene whose rigid bodies are timed free and held, and when (s) the timing starts.
RIGID_SCENE, RIGID_START = "rigid/floating_bodies", 1.0


def _held_walls(scene: Scene, sim: Simulation, motion: bool) -> Scene:
    """``scene`` with each rigid body turned into an obstacle wall where ``sim`` has it now (held by a
    motion that stands still when ``motion``, else a still wall)."""
    import numpy as np

    from augmpm.validation.rigid import placed

    data = scene.model_dump(mode="json", exclude_none=True)
    walls = data["walls"]
    for spec, (x, y, angle, *_) in zip(scene.rigid_bodies, sim.rigid_bodies, strict=True):
        body = spec.model_dump()
        if body["shape"] == "circle":
            wall = {"type": "circle", "center": [x, y], "radius": body["radius"], "side": "outside"}
        else:
            outline = placed(np.array(body["vertices"]), x, y, angle)
            wall = {"type": "polygon", "vertices": outline.tolist(), "side": "outside"}
        if motion:
            wall["motion"] = {"type": "constant", "velocity": [0.0, 0.0]}
        walls.append(wall)
    return Scene.from_dict({**data, "rigid_bodies": []})


def bench_rigid(steps: int, threads: int) -> list[dict]:
    """The cost of two-way coupling: :data:`RIGID_SCENE` from its state at :data:`RIGID_START` with its
    bodies free, against the same state with the bodies held where they are (walls that may move, and
    still walls), both methods, interleaved; the ratio of their step times."""
    scene = load_scene(RIGID_SCENE)
    rows = []
    for m in METHODS:
        free = Simulation(scene, m, threads=threads)
        free.step(round(RIGID_START / free.dt))
        state = free.checkpoint()
        sims = {"free": free}
        for label, motion in (("held", True), ("still", False)):
            sims[label] = Simulation(_held_walls(scene, free, motion), m, threads=threads)
            # The material's state as it is; the bodies' poses stay with the free run.
            sims[label].restore({**state, "wall_pose": state["wall_pose"][:0], "body_kick": state["body_kick"][:0]})
        result = interleaved(sims, steps, rounds=4)
        per_step = {k: r["seconds"] / r["steps"] if r["steps"] else math.nan for k, r in result.items()}
        rows.append(
            {
                "case": "rigid_coupling",
                "method": m,
                "threads": threads,
                **result["free"],
                "free_over_held": per_step["free"] / per_step["held"],
                "free_over_still": per_step["free"] / per_step["still"],
            }
        )
    return rows


def machine_roofs(threads: int, mebibytes: int = 64) -> dict:
    """The machine's measured roofs: memory bandwidth (GB/s, STREAM's add: two arrays of ``mebibytes`` MiB
    read and one written per thread, on ``threads`` threads at once, at most 8 (1.5 GiB); numpy leaves the GIL
    while it adds; best of 5) and peak f64 arithmetic (GFLOP/s, a 1,024² matrix product, 2n³ operations, through numpy's
    BLAS on its own threads; best of 5)."""
    import threading

    import numpy as np

    threads = min(threads, 8)
    n = mebibytes * 2**20 // 8
    arrays = [(np.ones(n), np.ones(n), np.empty(n)) for _ in range(threads)]
    best = math.inf
    for _ in range(5):
        workers = [threading.Thread(target=np.add, args=(a, b), kwargs={"out": c}) for a, b, c in arrays]
        t = time.perf_counter()
        for w in workers:
            w.start()
        for w in workers:
            w.join()
        best = min(best, time.perf_counter() - t)
    bandwidth = 3 * 8 * n * threads / best
    m = np.ones((1024, 1024)) * 0.5
    m @ m
    best = math.inf
    for _ in range(5):
        t = time.perf_counter()
        m @ m
        best = min(best, time.perf_counter() - t)
    return {"bandwidth_GBps": bandwidth / 1e9, "peak_GFLOPs": 2 * 1024**3 / best / 1e9, "threads": threads}


def stage_bytes(precision: str, dim: int, keeps_f: bool = False) -> dict[str, int]:
    """Bytes of particle data each per-particle stage of a fluid step reads and writes, per particle
    (the engine's per-particle arrays: x, v, c, F where a material keeps it, J, mass, V0, body, density;
    grid nodes are not counted, their 3^D per particle stay in cache). ``density`` moves nothing: it is the
    grid density's mass scatter, and the bench fluid's density is ρ0/J (the default), whose J-bar sums ride
    on P2G and G2P; ``p2g`` reads x, v, c, (F), J, mass, V0, body and writes the density; ``g2p`` reads x,
    v, c, (F), J, body and mass, and writes x, v, c, (F) and J."""
    r = 4 if precision == "f32" else 8
    vector, matrix, index = dim * r, dim * dim * r, 4
    f = matrix if keeps_f else 0
    return {
        "density": 0,
        "p2g": 2 * vector + matrix + f + 3 * r + index + r,
        "g2p": (2 * vector + matrix + f + r + index + r) + (2 * vector + matrix + f + r),
    }


def run_bench(
    quick: bool = False,
    fig1: Path = DEFAULT_FIG1,
    threads: int | None = None,
    sizes: tuple[int, ...] | None = None,
    log=print,
    peers: Path | None = None,
    ops: bool = False,
) -> dict:
    """Every case; returns the report (also what ``--json`` writes). With ``ops``, also each stage's
    instructions and floating-point operations per particle-step, counted under callgrind
    (:mod:`augmpm.opcount`) on the 256² dam break (128² with ``quick``)."""
    from augmpm import _core
    from augmpm.opcount import OpCountError, count_ops, require_tools
    from augmpm.simulation import resolve_threads

    fig1 = scene_path(fig1)
    if not fig1.is_file():
        raise _core.SceneError(f"--fig1: {fig1} not found (a scene file, or a shipped scene's name)")
    if peers is not None and not (Path(peers) / "run.sh").is_file():
        raise _core.SceneError(f"--peers: {Path(peers) / 'run.sh'} not found (the folder of the peer engines' run.sh)")
    if ops:
        try:
            require_tools()
        except OpCountError as e:
            raise _core.SceneError(f"--ops: {e}") from None
    threads = resolve_threads(threads)
    sizes = sizes or ((128, 256) if quick else (128, 256, 512))
    thread_counts = tuple(sorted({1, threads}))
    report = {"machine": _machine(threads), "quick": quick, "rows": []}
    log(f"machine roofs (memory bandwidth, f64 peak) on {threads} threads …")
    report["roofs"] = machine_roofs(threads)
    if ops:
        # First: a failure under valgrind then costs no other measurement.
        res = 128 if quick else 256
        log(f"operations per particle-step under callgrind, dam break {res}², one thread, 3 steps after 3 …")
        report["ops"] = [count_ops(res, m, p) for p in PRECISIONS for m in METHODS]
    log(f"fig1 ({fig1}), {2_000 if quick else FIG1_STEPS} steps, naive and augmented …")
    report["rows"] += bench_fig1(fig1, 2_000 if quick else FIG1_STEPS, threads)
    steps = {128: 200, 256: 60, 512: 20} if quick else {128: 1000, 256: 300, 512: 60}
    for res in sizes:
        log(f"dam break {res}², {steps[res]} steps, threads {thread_counts} …")
        report["rows"] += bench_dam_break(res, steps[res], thread_counts)
    scaling = {256: (10, 50), 512: (3, 20)} if quick else {256: (20, 200), 512: (5, 50)}
    for res in (r for r in sizes if r in scaling and threads > 1):
        chunk, warm_up = scaling[res]
        log(f"thread scaling {res}²: 1 and {threads} threads, {threads} one-thread runs at once, {warm_up} steps in …")
        report["rows"].append(bench_scaling(res, chunk, threads, warm_up))
    steps3 = {32: 40, 64: 8} if quick else {32: 200, 64: 40, 128: 8}
    for res in steps3:
        log(f"dam break 3D {res}³, {steps3[res]} steps, threads {threads} …")
        report["rows"] += bench_dam_break(res, steps3[res], (threads,), dim=3)
    moving_steps = 300 if quick else 1_500
    log(f"moving walls ({', '.join(MOVING_SCENES)}), {moving_steps} steps, moving and still …")
    report["rows"] += bench_moving(moving_steps, threads)
    rigid_steps = 300 if quick else 1_500
    log(f"rigid bodies ({RIGID_SCENE}), {rigid_steps} steps, free and held …")
    report["rows"] += bench_rigid(rigid_steps, threads)
    log("output cost (fig1 with frames, images and animation) …")
    report["rows"] += bench_output(fig1, 1_000 if quick else FIG1_STEPS, threads)
    if peers is not None:
        peer_steps = {256: 60, 512: 20} if quick else {256: 200, 512: 60}
        for res in (256, 512) if not quick else (256,):
            log(f"peers ({peers}/run.sh) against the dam break {res}², {peer_steps[res]} steps, 3 rounds …")
            report["rows"] += bench_peers(peers, res, peer_steps[res], threads, log=log)
    return report


def _machine(threads: int) -> dict:
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": commit.stdout.strip() or "unknown",
        "cpu": cpu,
        "cores": os.cpu_count(),
        "threads": threads,
        "python": platform.python_version(),
    }


def format_report(report: dict) -> str:
    """Markdown tables of a report."""
    m = report["machine"]
    lines = [f"Machine: {m['cpu']}, {m['cores']} cores; {m['date']}, commit {m['commit']}.", ""]
    fig1 = [r for r in report["rows"] if r["case"] == "fig1"]
    if fig1:
        lines += [
            "| Fig. 1 scene | threads | steps run | time for 10,000 steps (s) | authors (s) | speed-up |",
            "|---|---|---|---|---|---|",
        ]
        for r in fig1:
            lines.append(
                f"| {r['method']} | {r['threads']} | {r['steps']} | {r['seconds_10k_steps']:.2f} "
                f"| {AUTHORS_FIG1_SECONDS[r['method']]} | {r['speedup_vs_authors']:.1f}× |"
            )
        lines.append("")
    dam = [r for r in report["rows"] if r["case"].startswith("dam_break")]

    def size(r: dict) -> str:
        res = r["case"].removeprefix("dam_break_3d_").removeprefix("dam_break_")
        return f"{res}³" if r.get("dim") == 3 else f"{res}²"

    if dam:
        lines += [
            "| dam break | particles | precision | method | threads | M particle-steps/s | aug./naive | vs 1 thread "
            "| peak B/particle (measured) | B/particle without grid |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in dam:
            speedup = f"{r['speedup_over_1_thread']:.2f}×" if "speedup_over_1_thread" in r else "–"
            mem = r["memory"]
            if "error" in r:
                lines.append(
                    f"| {size(r)} | {r['particles']:,} | {r['precision']} "
                    f"| {r['method']} | {r['threads']} | failed: {r['error']} | | | | |"
                )
                continue
            lines.append(
                f"| {size(r)} | {r['particles']:,} | {r['precision']} | {r['method']} "
                f"| {r['threads']} "
                f"| {r['particle_steps_per_s'] / 1e6:.1f} | {r['augmented_over_naive']:.2f} | {speedup} "
                f"| {mem['peak_bytes_per_particle']:.0f} | {mem['per_particle_without_grid']:.0f} |"
            )
        for r in dam:
            if "target_particle_steps_per_s" in r and "error" not in r:
                rate, target = r["particle_steps_per_s"], r["target_particle_steps_per_s"]
                lines += [
                    "",
                    f"3D target: the {size(r)} dam break ({r['particles']:,} particles), {r['precision']} "
                    f"{r['method']} on {r['threads']} threads, {rate / 1e6:.1f} M particle-steps/s against "
                    f"≥ {target / 1e6:.0f} M: {'met' if rate >= target else f'missed by {target / rate:.2f}×'}.",
                ]
        lines += ["", "| stage split (% of step) | " + " | ".join(STAGES) + " |", "|---|" + "---|" * len(STAGES)]
        for r in dam + fig1:
            total = sum(r["stages_s"].values()) or 1.0
            cells = " | ".join(f"{100 * r['stages_s'][s] / total:.0f}" for s in STAGES)
            label = f"{r['case']} {r.get('precision', 'f64')} {r['method']} {r['threads']}t"
            lines.append(f"| {label} | {cells} |")
        lines.append("")
        timed = [r for r in dam if "error" not in r]
        lines += _roofline(report, timed) + _operations(report, timed)
    moving = [r for r in report["rows"] if r["case"].startswith("moving_")]
    if moving:
        lines += ["| moving walls | method | particles | steps | step time, moving / still walls |"]
        lines += ["|---|---|---|---|---|"]
        for r in moving:
            lines.append(
                f"| {r['case'].removeprefix('moving_')} | {r['method']} | {r['particles']:,} | {r['steps']} "
                f"| {r['moving_over_still']:.2f}× |"
            )
        lines.append("")
    rigid = [r for r in report["rows"] if r["case"] == "rigid_coupling"]
    if rigid:
        lines += ["| rigid bodies (floating_bodies from 1 s) | particles | steps | free / held | free / still walls |"]
        lines += ["|---|---|---|---|---|"]
        for r in rigid:
            lines.append(
                f"| {r['method']} | {r['particles']:,} | {r['steps']} "
                f"| {r['free_over_held']:.2f}× | {r['free_over_still']:.2f}× |"
            )
        lines.append("")
    scaling = [r for r in report["rows"] if r["case"].startswith("scaling_")]
    if scaling:
        lines += [
            "| thread scaling (naive f64 dam break; medians of rounds) | particles | threads | speed-up over 1 thread "
            "| the machine's ceiling: as many one-thread runs at once | speed-up / ceiling | target |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in scaling:
            low, high = min(r["speedup_rounds"]), max(r["speedup_rounds"])
            lines.append(
                f"| {r['case'].removeprefix('scaling_')}², after {r['warm_up']} steps | {r['particles']:,} "
                f"| {r['threads']} | {r['speedup']:.2f}× ({low:.2f}–{high:.2f}×, {r['rounds']}) "
                f"| {r['ceiling']:.2f}× | {r['speedup'] / r['ceiling']:.2f} | ≥ {SCALING_TARGET}× |"
            )
        lines += ["", "| thread scaling per stage (summed times, 1 thread / N) | " + " | ".join(STAGES) + " |"]
        lines += ["|---|" + "---|" * len(STAGES)]
        for r in scaling:
            cells = " | ".join(f"{r['stage_speedups'][s]:.2f}×" if s in r["stage_speedups"] else "–" for s in STAGES)
            lines.append(f"| {r['case'].removeprefix('scaling_')}², {r['threads']} threads | {cells} |")
        lines.append("")
    peers = [r for r in report["rows"] if r["case"].startswith("peers_")]
    if peers:
        lines += [
            "| dam break vs peers (mpm88, f32) | particles | precision | method | threads "
            "| M particle-steps/s (median of rounds) | peers (M) | over the faster peer | target |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in peers:
            theirs = ", ".join(f"{k} {v / 1e6:.1f}" for k, v in sorted(r["peers"].items()))
            if r["target_over_faster_peer"] is not None:
                target = f"≥ {r['target_over_faster_peer']}×"
            else:
                target = f"aug./naive {r['augmented_over_naive']:.2f} (≤ {r['target_augmented_over_naive']})"
            lines.append(
                f"| {r['case'].removeprefix('peers_')}² | {r['particles']:,} | {r['precision']} | {r['method']} "
                f"| {r['threads']} | {r['particle_steps_per_s'] / 1e6:.1f} | {theirs} "
                f"| {r['over_faster_peer']:.2f}× | {target} |"
            )
        lines.append("")
    out = [r for r in report["rows"] if r["case"] == "output"]
    if out:
        lines += [
            "| output cost (Fig. 1; medians of rounds) | steps | frames | simulation (s) | with output (s) "
            "| output share (rounds) | target |"
        ]
        lines += ["|---|---|---|---|---|---|---|"]
        for r in out:
            # Reports from before the rounds had one run of each.
            low, high = r.get("output_fraction_range", [r["output_fraction"]] * 2)
            lines.append(
                f"| {r['method']} | {r['steps']} | {r['frames']} | {r['simulation_s']:.2f} "
                f"| {r['run_with_output_s']:.2f} | {100 * r['output_fraction']:.0f}% "
                f"({100 * low:.0f}–{100 * high:.0f}%, {r.get('rounds', 1)}) | ≤ {100 * OUTPUT_TARGET:.0f}% |"
            )
    return "\n".join(lines)


def _roofline(report: dict, rows: list[dict]) -> list[str]:
    """The roofline table: per dam-break row and per-particle stage, the bytes a particle-step moves, the
    bandwidth the stage reached (those bytes at its measured rate) and its share of the machine's."""
    roofs = report.get("roofs")
    if not roofs or not rows:
        return []
    stages = ("density", "p2g", "g2p")
    lines = [
        f"Roofline: memory bandwidth {roofs['bandwidth_GBps']:.1f} GB/s and f64 peak "
        + f"{roofs['peak_GFLOPs']:.0f} GFLOP/s measured on {roofs['threads']} threads. Per stage: particle "
        + "bytes per particle-step / GB/s reached (share of the bandwidth)"
        + ("; the operations per particle-step are below." if report.get("ops") else "."),
        "",
        "| dam break, config | " + " | ".join(stages) + " |",
        "|---|" + "---|" * len(stages),
    ]
    for r in rows:
        moved = stage_bytes(r["precision"], r.get("dim", 2))
        cells = []
        for stage in stages:
            seconds = r["stages_s"].get(stage, 0.0)
            if seconds <= 0 or moved[stage] == 0:
                cells.append("–")
                continue
            rate = moved[stage] * r["particles"] * r["steps"] / seconds / 1e9
            cells.append(f"{moved[stage]} B / {rate:.1f} ({100 * rate / roofs['bandwidth_GBps']:.0f}%)")
        label = f"{r['case']} {r['precision']} {r['method']} {r['threads']}t"
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines.append("")
    return lines


def _operations(report: dict, rows: list[dict]) -> list[str]:
    """The operations table (``--ops``): per counted configuration and stage, the instructions, floating-point
    operations (those in scalar instructions) and division and square-root instructions per particle-step,
    and the rates those counts make at each timed row's stage time (the step's: the sum of its stage times):
    instructions and operations per second, the latter's share of the machine's f64 peak (measured on the
    report's threads)."""
    counted = report.get("ops")
    if not counted:
        return []
    roofs = report.get("roofs") or {}
    peak = roofs.get("peak_GFLOPs")
    first = counted[0]
    lines = [
        f"Operations per particle-step, counted under callgrind on one thread (steps {first['warm_up'] + 1}–"
        + f"{first['warm_up'] + first['steps']} of the dam break; `--ops`): flops are adds, subtracts, multiplies, "
        + "divisions and square roots, one a lane, and fused multiply-adds, two a lane, every lane of a packed "
        + "instruction counted; of them, those in scalar (one-lane) instructions. The rates are those counts at "
        + "each timed row's stage time"
        + (
            f"; the flop rate's share of the f64 peak ({peak:.0f} GFLOP/s on {roofs['threads']} threads)."
            if peak
            else "."
        ),
        "",
        "| dam break, config | stage | instructions | flops (scalar) | division, root instructions "
        + "| G instructions/s | GFLOP/s |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in counted:
        timed = [
            r
            for r in rows
            if (r["case"], r["precision"], r["method"]) == (c["case"], c["precision"], c["method"])
            and r.get("dim", 2) == 2
        ]
        for stage, n in c["stages"].items():
            if stage not in ("boundary", "p2g", "g2p", "step") or n["instructions"] < 1:
                continue
            for r in timed or [None]:
                label = f"{c['case']} {c['precision']} {c['method']}" + (f" {r['threads']}t" if r else "")
                rates = ["–", "–"]
                seconds = 0.0
                if r is not None:
                    seconds = sum(r["stages_s"].values()) if stage == "step" else r["stages_s"].get(stage, 0.0)
                if seconds > 0:
                    per_s = r["particles"] * r["steps"] / seconds
                    gflops = n["flops"] * per_s / 1e9
                    share = f" ({100 * gflops / peak:.0f}%)" if peak else ""
                    rates = [f"{n['instructions'] * per_s / 1e9:.1f}", f"{gflops:.1f}{share}"]
                lines.append(
                    f"| {label} | {stage} | {n['instructions']:.0f} | {n['flops']:.0f} ({n['scalar_flops']:.0f}) "
                    + f"| {n['div_sqrt']:.1f} | {rates[0]} | {rates[1]} |"
                )
    lines.append("")
    return lines


def _main_worker(argv: list[str]) -> None:
    """Subprocess entry of the memory measurement (``python -m augmpm.bench memory RES METHOD``)."""
    if argv[0] == "baseline":
        print(json.dumps({"max_rss": _max_rss_bytes()}))
        return
    _, res, method, precision, dim = argv
    sim = Simulation(_dam_break(int(res), int(dim)).model_copy(update={"precision": precision}), method)
    sim.step(2)
    print(json.dumps({"max_rss": _max_rss_bytes(), "particles": sim.num_particles, "accounted": sim.memory_use()}))


if __name__ == "__main__":
    _main_worker(sys.argv[1:])
