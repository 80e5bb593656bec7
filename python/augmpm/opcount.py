"""Instructions and floating-point operations per particle-step of each stage, counted with callgrind.

The machines this project is measured on expose no hardware counters, so the roofline's operations are
counted instead of sampled: a scene is stepped on one thread under valgrind's callgrind, collecting only
inside the engine's step, with a dump of the counts before each call of the engine's stage timer (never
inlined for this): each dump holds one stage, the first of a step also the end of the step before. Every
executed instruction is then weighed by the floating-point operations it performs, read from the disassembly
of its object (``objdump``): an add, subtract, multiply, divide or square root is one operation a lane, a
fused multiply-add two, a horizontal add one an output lane; comparisons, minima, maxima, conversions and
logic are none. Every lane of a packed instruction counts, used or not (f32's 2D vectors fill two of four).
The counts are exact for the code that ran under valgrind, which reports a CPU without AVX-512 to the
program: code that picks its path at run time (libm's ``exp``) may run another path natively, and AVX-512
code (the zmm rules below) cannot run under valgrind at all.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

# The engine's step and its stage timer (their demangled names, in both precisions' cores). The step
# toggles counting; a dump before each call of the timer closes the stage it times.
STEP_FUNCTION = "*step_here"
LAP_FUNCTION = "*::simulation::Lap::add_to"

_ARITHMETIC = re.compile(r"^v?(?:add|sub|mul|div|sqrt|addsub)(ss|sd|ps|pd)$")
_HORIZONTAL = re.compile(r"^v?h(?:add|sub)(ps|pd)$")
_FUSED = re.compile(r"^v?f(?:n?m(?:add|sub)|maddsub|msubadd)(?:132|213|231)(ss|sd|ps|pd)$")
# x87, with objdump's size suffixes on memory operands (`faddl`: a double).
_X87 = re.compile(r"^f(?:add|sub|subr|mul|div|divr)[psl]?$|^fsqrt$")
# An object named by id: `(id) name` where it is first given, `(id)` after.
_NAMED = re.compile(r"\((\d+)\)(?: (.*))?$")


class OpCountError(RuntimeError):
    """Counting could not run (valgrind or objdump missing, valgrind failed) or its output was not
    understood."""


@dataclass(frozen=True)
class Ops:
    """What one instruction does: floating-point operations, whether they are scalar (one lane), and whether
    it divides or takes a square root (long latency, not pipelined like the rest; counted as instructions,
    whatever their lanes)."""

    flops: int = 0
    scalar: bool = True
    divide: bool = False


def instruction_ops(mnemonic: str, operands: str = "") -> Ops:
    """The floating-point operations of an x86-64 instruction as ``objdump`` prints it: one per lane for
    an SSE/AVX add, subtract, multiply, divide or square root (and add-subtract), two per lane for a fused
    multiply-add, one per output lane for a horizontal add or subtract, one for an x87 add, subtract,
    multiply, divide or square root; the lanes from the widest register among the operands (xmm 128 bits,
    ymm 256, zmm 512; an AVX-512 mask is not read)."""
    if m := _ARITHMETIC.match(mnemonic):
        kind, per_lane = m.group(1), 1
    elif m := _FUSED.match(mnemonic):
        kind, per_lane = m.group(1), 2
    elif m := _HORIZONTAL.match(mnemonic):
        kind, per_lane = m.group(1), 1
    elif _X87.match(mnemonic):
        return Ops(1, True, mnemonic.startswith(("fdiv", "fsqrt")))
    else:
        return Ops()
    divide = mnemonic.lstrip("v").startswith(("div", "sqrt"))
    if kind in ("ss", "sd"):
        return Ops(per_lane, True, divide)
    width = 512 if "%zmm" in operands else 256 if "%ymm" in operands else 128
    lanes = width // (32 if kind == "ps" else 64)
    return Ops(per_lane * lanes, False, divide)


@dataclass
class Dump:
    """One callgrind dump: what triggered it and the instructions executed at each (object, address)
    since the dump before, calls' inclusive costs left out."""

    trigger: str
    total: int
    counts: dict[tuple[str, int], int] = field(default_factory=dict)


def _position(token: str, last: int) -> int:
    if token == "*":
        return last
    if token[0] in "+-":
        return last + int(token, 0)
    return int(token, 0)


def parse_dump(text: str, objects: dict[str, str] | None = None) -> Dump:
    """A callgrind output file written with ``--dump-instr=yes`` (positions ``instr line``, event ``Ir``),
    name and position compression included. Checks that the instruction counts add up to its totals.
    ``objects`` holds the object names by id across the dumps of one run, in order (an id keeps its name
    for the whole run, and a later dump may use it without giving it again)."""
    objects = {} if objects is None else objects
    trigger, totals, obj = "", None, "???"
    counts: dict[tuple[str, int], int] = defaultdict(int)
    # `skip_next`: the line after `calls=` (the call's inclusive cost) or `jump=`/`jcnd=` (no cost).
    last, skip_next = 0, False
    positions = ["instr", "line"]
    for line in text.splitlines():
        if not line or line.startswith("#"):
            continue
        head = line[0]
        if head.isdigit() or head in "+-*":
            fields = line.split()
            try:
                address = _position(fields[0], last)
            except ValueError:
                raise OpCountError(f"callgrind: a position that is not a number: {line!r}") from None
            last = address
            if skip_next:
                skip_next = False
                continue
            if len(fields) < len(positions) + 1:
                raise OpCountError(f"callgrind: a cost line without its {positions} and cost: {line!r}")
            counts[(obj, address)] += int(fields[len(positions)])
            continue
        key, _, value = line.partition("=") if "=" in line.split(":", 1)[0] else line.partition(":")
        value = value.strip()
        if key in ("ob", "cob"):
            # A called object's name may be given first on a `cob=` line; later `ob=(id)` lines refer to it.
            m = _NAMED.match(value)
            if m and m.group(2) is not None:
                objects[m.group(1)] = m.group(2)
            if key == "ob":
                obj = objects.get(m.group(1), "???") if m else value
        elif key in ("calls", "jump", "jcnd"):
            skip_next = True
        elif key == "positions":
            positions = value.split()
            if positions[0] != "instr":
                raise OpCountError(f"callgrind: positions {value!r}: run it with --dump-instr=yes")
        elif key == "events" and value.split()[0] != "Ir":
            raise OpCountError(f"callgrind: events {value!r}: the first must be Ir")
        elif key == "desc" and value.startswith("Trigger:"):
            trigger = value.removeprefix("Trigger:").strip()
        elif key == "totals" or (key == "summary" and totals is None):
            totals = int(value.split()[0])
    total = sum(counts.values())
    if totals is not None and total != totals:
        raise OpCountError(f"callgrind: instruction counts add up to {total}, its totals say {totals}")
    return Dump(trigger, total, dict(counts))


def disassemble(path: str, addresses: set[int]) -> dict[int, tuple[str, str]]:
    """The mnemonic and operands of each instruction at ``addresses`` (the object's own, as callgrind
    gives them for shared objects) in the object at ``path``, by ``objdump -d``."""
    out = subprocess.run(
        ["objdump", "-d", "-w", "--no-show-raw-insn", path],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    found: dict[int, tuple[str, str]] = {}
    for line in out.splitlines():
        address, tab, rest = line.partition(":\t")
        if not tab:
            continue
        try:
            a = int(address.strip(), 16)
        except ValueError:
            continue
        if a in addresses:
            mnemonic, _, operands = rest.strip().partition(" ")
            found[a] = (mnemonic, operands.strip())
    return found


def weigh(dumps: list[Dump]) -> tuple[list[dict], int]:
    """Per dump: instructions, floating-point operations, those in scalar instructions, and division and
    square-root instructions; and the instructions that could not be read from their object's disassembly (objects
    outside the file system, such as the vDSO), which count no operations."""
    wanted: dict[str, set[int]] = defaultdict(set)
    for d in dumps:
        for obj, address in d.counts:
            wanted[obj].add(address)
    table: dict[tuple[str, int], Ops] = {}
    for obj, addresses in wanted.items():
        if not Path(obj).is_file():
            continue
        for a, (mnemonic, operands) in disassemble(obj, addresses).items():
            table[(obj, a)] = instruction_ops(mnemonic, operands)
    unread = 0
    out = []
    for d in dumps:
        flops = scalar = divide = 0
        for key, n in d.counts.items():
            ops = table.get(key)
            if ops is None:
                unread += n
                continue
            flops += n * ops.flops
            scalar += n * ops.flops * ops.scalar
            divide += n * ops.divide
        out.append({"instructions": d.total, "flops": flops, "scalar_flops": scalar, "div_sqrt": divide})
    return out, unread


def missing_tools() -> list[str]:
    """The tools counting needs that are not on PATH."""
    return [tool for tool in ("valgrind", "objdump") if shutil.which(tool) is None]


def require_tools() -> None:
    """Raises :class:`OpCountError` naming the tools counting needs that are not on PATH."""
    if missing := missing_tools():
        raise OpCountError(f"counting operations needs {' and '.join(missing)} on PATH, not found")


def load_extension(name: str, path: Path | str):
    """The engine extension module at ``path`` (a built ``_core`` file), imported as ``<name>._core`` beside
    the installed one."""
    import importlib.machinery
    import importlib.util

    module_name = f"{name}._core"
    loader = importlib.machinery.ExtensionFileLoader(module_name, str(path))
    spec = importlib.util.spec_from_file_location(module_name, path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def count_ops(resolution: int, method: str, precision: str, warm_up: int = 3, steps: int = 3) -> dict:
    """Instructions and floating-point operations per particle-step of each stage of the 2D dam break
    (``augmpm.bench.dam_break_scene``) at ``resolution`` in ``precision``: :func:`count_scene_ops` with the
    case and precision named. Takes about half a minute at 256² (valgrind runs ~50× slower)."""
    from augmpm.bench import dam_break_scene

    scene = dam_break_scene(resolution).model_copy(update={"precision": precision})
    counted = count_scene_ops(scene.to_json(), method, warm_up, steps)
    return {"case": f"dam_break_{resolution}", "method": method, "precision": precision, **counted}


#: Most of the counted instructions that may lie outside every object objdump can read (the vDSO's clock).
UNREAD_LIMIT = 1e-3


def count_scene_ops(
    scene: str, method: str, warm_up: int = 3, steps: int = 3, engine: Path | str | None = None
) -> dict:
    """Instructions and floating-point operations per particle-step of each stage of the scene (its JSON)
    stepped by ``method`` on one thread, over ``steps`` steps after ``warm_up``: the stages of the engine's
    stage times (the first also holds the work after the last stage of the step before), and the whole
    step (``step``, their sum). ``engine`` is the extension to count (a built ``_core`` file; the installed
    one by default)."""
    require_tools()
    if steps < 1 or warm_up < 0:
        raise OpCountError(f"steps {steps} and warm-up {warm_up}: at least one step counted, none negative")
    with tempfile.TemporaryDirectory(prefix="augmpm-ops-") as tmp:
        out = Path(tmp) / "callgrind.out"
        info = Path(tmp) / "info.json"
        scene_file = Path(tmp) / "scene.json"
        scene_file.write_text(scene)
        cmd = [
            "valgrind",
            "--tool=callgrind",
            "--dump-instr=yes",
            "--collect-jumps=no",
            "--separate-threads=no",
            "--collect-atstart=no",
            f"--toggle-collect={STEP_FUNCTION}",
            f"--dump-before={LAP_FUNCTION}",
            f"--callgrind-out-file={out}",
            sys.executable,
            "-m",
            "augmpm.opcount",
            str(scene_file),
            method,
            str(warm_up),
            str(steps),
            str(info),
            *([str(Path(engine).resolve())] if engine is not None else []),
        ]
        # Valgrind's options from the environment or a .valgrindrc would change what it writes.
        env = {k: v for k, v in os.environ.items() if k != "VALGRIND_OPTS"}
        run = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp)
        if run.returncode != 0:
            raise OpCountError(f"valgrind exited with {run.returncode}: {run.stderr.strip()[-2000:]}")
        meta = json.loads(info.read_text())
        files = []
        for p in Path(tmp).glob("callgrind.out.*"):
            if not p.suffix[1:].isdigit():
                raise OpCountError(f"callgrind wrote {p.name}, not one file a dump")
            files.append(p)
        files.sort(key=lambda p: int(p.suffix[1:]))
        objects: dict[str, str] = {}
        dumps = [parse_dump(p.read_text(), objects) for p in files]
    # The step calls the timer once a stage, in the order of its stage times (`stage_times()`, the order
    # the engine's `StageTimes` lists them and `step_here` calls `Lap::add_to`): the dump before the call
    # that ends stage k holds stage k.
    names = meta["stages"]
    per_step = len(names)
    if len(dumps) != per_step * (warm_up + steps):
        raise OpCountError(
            f"callgrind wrote {len(dumps)} dumps, not {per_step} a step for {warm_up + steps} steps: did the "
            + "step's stages change, or does the extension lack its symbols (Lap::add_to, step_here)?"
        )
    counted = dumps[-per_step * steps :]
    for d in counted:
        if not d.trigger.endswith("Lap::add_to"):
            raise OpCountError(f"a dump triggered by {d.trigger!r}, not the stage timer")
    weighed, unread = weigh(counted)
    total = sum(d.total for d in counted)
    if total == 0:
        raise OpCountError("callgrind counted nothing inside the step (is step_here still a function of its own?)")
    if unread > UNREAD_LIMIT * total:
        raise OpCountError(
            f"{unread / total:.1%} of the counted instructions lie outside the objects objdump could read"
        )
    particle_steps = meta["particles"] * steps
    stages: dict[str, dict[str, float]] = {name: defaultdict(float) for name in names}
    for i, w in enumerate(weighed):
        for k, v in w.items():
            stages[names[i % per_step]][k] += v / particle_steps
    stages["step"] = {k: sum(s[k] for s in stages.values()) for k in weighed[0]}
    return {
        "particles": meta["particles"],
        "warm_up": warm_up,
        "steps": steps,
        "stages": {k: dict(v) for k, v in stages.items()},
        "unread_share": unread / total,
    }


def _main_worker(argv: list[str]) -> None:
    """Run under callgrind by :func:`count_scene_ops`: steps the scene and writes what the counts are of."""
    from augmpm.simulation import memory_limit

    scene_file, method, warm_up, steps, info, *engine = argv
    if engine:
        core = load_extension("counted", engine[0])
    else:
        from augmpm import _core as core
    sim = core.Simulation(Path(scene_file).read_text(), method, 1, memory_limit())
    Path(info).write_text(json.dumps({"particles": sim.num_particles, "stages": list(sim.stage_times())}))
    sim.step(int(warm_up))
    sim.step(int(steps))


if __name__ == "__main__":
    _main_worker(sys.argv[1:])
