"""``augmpm.opcount``: each stage's instructions and floating-point operations, counted under callgrind."""

from __future__ import annotations

import pytest

from augmpm import bench, opcount
from augmpm.opcount import OpCountError, Ops, instruction_ops, parse_dump


@pytest.mark.parametrize(
    "mnemonic, operands, ops",
    [
        ("addsd", "%xmm1,%xmm0", Ops(1, True, False)),
        ("vmulss", "%xmm2,%xmm1,%xmm0", Ops(1, True, False)),
        ("divsd", "%xmm1,%xmm0", Ops(1, True, True)),
        ("sqrtsd", "%xmm0,%xmm0", Ops(1, True, True)),
        ("vfmadd231sd", "%xmm2,%xmm1,%xmm0", Ops(2, True, False)),
        ("vfnmsub132ss", "(%rax),%xmm1,%xmm0", Ops(2, True, False)),
        ("mulpd", "%xmm1,%xmm0", Ops(2, False, False)),
        ("subps", "0x10(%rsp),%xmm0", Ops(4, False, False)),
        ("vaddpd", "%ymm2,%ymm1,%ymm0", Ops(4, False, False)),
        ("vfmadd213ps", "%ymm2,%ymm1,%ymm0", Ops(16, False, False)),
        ("vdivpd", "%zmm2,%zmm1,%zmm0", Ops(8, False, True)),
        ("vfmaddsub231pd", "%xmm2,%xmm1,%xmm0", Ops(4, False, False)),
        ("addsubpd", "%xmm1,%xmm0", Ops(2, False, False)),
        # A horizontal add: one add an output lane.
        ("haddpd", "%xmm1,%xmm0", Ops(2, False, False)),
        ("vhaddps", "%ymm2,%ymm1,%ymm0", Ops(8, False, False)),
        # x87.
        ("faddp", "%st,%st(1)", Ops(1, True, False)),
        ("fsqrt", "", Ops(1, True, True)),
        ("faddl", "0x8(%rax)", Ops(1, True, False)),
        ("fdivrp", "%st,%st(1)", Ops(1, True, True)),
        # Integer, logic, comparisons, minima and conversions are no floating-point operations.
        ("add", "$0x8,%rsp", Ops()),
        ("paddd", "%xmm1,%xmm0", Ops()),
        ("maxsd", "%xmm1,%xmm0", Ops()),
        ("ucomisd", "%xmm1,%xmm0", Ops()),
        ("cvtsi2sd", "%rax,%xmm0", Ops()),
        ("xorpd", "%xmm0,%xmm0", Ops()),
        ("fxch", "%st(1)", Ops()),
        ("fld", "(%rax)", Ops()),
    ],
)
def test_instruction_ops_count_one_per_lane_and_two_per_fused_multiply_add(mnemonic, operands, ops):
    assert instruction_ops(mnemonic, operands) == ops


_DUMP = """# callgrind format
version: 1
creator: callgrind-3.19.0
part: 3

desc: Timerange: Basic block 10 - 20
desc: Trigger: --dump-before=augmpm_core::simulation::Lap::add_to

positions: instr line
events: Ir
summary: 117

ob=(3) /usr/lib/libm.so.6
fl=(1) ???
fn=(10) exp
0x1000 0 5
+4 * 5
+0x8 3 2

ob=(7) /tmp/core.so
fl=(2) ???
fn=(11) p2g
0x2000 0 10
cob=(3)
cfn=(10)
calls=2 0x1000 0
+3 0 12
* 0 1
-3 * 80
cob=(8) /tmp/other.so
cfn=(12) f
calls=1 0x10 0
+6 0 40

ob=(8)
fn=(12)
0x10 0 7
ob=(3)
fn=(10)
0x1000 0 7

totals: 117
"""


def test_parse_dump_reads_compressed_names_and_positions_and_leaves_out_calls():
    """Names given once by id, positions relative (decimal and hex) or repeated, and the inclusive cost on
    the line after each `calls=` left out: the exclusive counts add up to the dump's totals."""
    d = parse_dump(_DUMP)
    assert d.trigger == "--dump-before=augmpm_core::simulation::Lap::add_to"
    assert d.total == 117
    assert d.counts == {
        ("/usr/lib/libm.so.6", 0x1000): 5 + 7,
        ("/usr/lib/libm.so.6", 0x1004): 5,
        ("/usr/lib/libm.so.6", 0x100C): 2,
        ("/tmp/core.so", 0x2000): 10 + 80,
        ("/tmp/core.so", 0x2003): 1,
        ("/tmp/other.so", 0x10): 7,
    }


def test_parse_dump_keeps_object_names_across_the_dumps_of_a_run():
    """An object named in an earlier dump of the run is known by its id alone in a later one."""
    objects: dict[str, str] = {}
    parse_dump(_DUMP, objects)
    later = "positions: instr line\nevents: Ir\nob=(7)\nfn=(11)\n0x2000 0 4\ntotals: 4\n"
    assert parse_dump(later, objects).counts == {("/tmp/core.so", 0x2000): 4}
    assert parse_dump(later).counts == {("???", 0x2000): 4}, "unknown without the run's names"


def test_parse_dump_skips_the_line_after_a_jump():
    """With jumps collected, a `jump=`/`jcnd=` line is followed by its source position without a cost."""
    jumps = _DUMP.replace("0x2000 0 10\n", "0x2000 0 10\njump=3 +9 0\n* 0\njcnd=1 2 +9 0\n* 0\n")
    assert parse_dump(jumps).counts == parse_dump(_DUMP).counts


def test_parse_dump_rejects_what_it_cannot_read():
    with pytest.raises(OpCountError, match="add up to 117, its totals say 118"):
        parse_dump(_DUMP.replace("totals: 117", "totals: 118"))
    with pytest.raises(OpCountError, match="--dump-instr=yes"):
        parse_dump(_DUMP.replace("positions: instr line", "positions: line"))
    with pytest.raises(OpCountError, match="not a number"):
        parse_dump(_DUMP.replace("+4 * 5", "+4x * 5"))


def test_operations_table_gives_rates_at_each_timed_rows_stage_time():
    """Counts per particle-step times a timed row's particle-steps per second in each stage: 100 flops a
    particle-step, 1,000 particles x 10 steps in 2 ms of P2G is 0.5 GFLOP/s, 1% of a 50 GFLOP/s peak."""
    row = {
        "case": "dam_break_128",
        "dim": 2,
        "precision": "f64",
        "method": "naive",
        "threads": 2,
        "particles": 1000,
        "steps": 10,
        "stages_s": {"sort": 1e-3, "p2g": 2e-3, "g2p": 1e-3},
    }
    n = {"instructions": 400.0, "flops": 100.0, "scalar_flops": 40.0, "div_sqrt": 3.0}
    step = {"instructions": 1000.0, "flops": 250.0, "scalar_flops": 100.0, "div_sqrt": 3.0}
    counted = {
        "case": "dam_break_128",
        "method": "naive",
        "precision": "f64",
        "warm_up": 3,
        "steps": 3,
        "stages": {"boundary": dict.fromkeys(n, 0.0), "p2g": n, "step": step},
    }
    report = {"roofs": {"bandwidth_GBps": 10.0, "peak_GFLOPs": 50.0, "threads": 2}, "ops": [counted]}
    lines = bench._operations(report, [row])
    assert "| dam_break_128 f64 naive 2t | p2g | 400 | 100 (40) | 3.0 | 2.0 | 0.5 (1%) |" in lines
    # The step: 1,000 instructions x 10,000 particle-steps in the stages' 4 ms.
    assert "| dam_break_128 f64 naive 2t | step | 1000 | 250 (100) | 3.0 | 2.5 | 0.6 (1%) |" in lines
    assert not any("| boundary |" in line for line in lines), "a stage that did nothing is left out"
    assert any(line.startswith("Operations per particle-step") and "steps 4–6" in line for line in lines)


def test_bench_ops_without_valgrind_is_a_clear_error(monkeypatch, capsys):
    from augmpm.cli import main

    monkeypatch.setattr(opcount.shutil, "which", lambda tool: None if tool == "valgrind" else "/usr/bin/" + tool)
    assert main(["bench", "--quick", "--ops"]) == 2
    assert "--ops: counting operations needs valgrind on PATH, not found" in capsys.readouterr().err


@pytest.mark.skipif(opcount.missing_tools() != [], reason="needs valgrind and objdump")
def test_count_ops_cuts_the_step_into_its_stages():
    """Counted under callgrind, the 128² naive dam break's stages add up to its step, every instruction is
    read from its object, and P2G does at least its 9 nodes' momentum and mass scatters (an affine product
    and sum, a weighted sum and a mass, 10 flops a node in 2D) and one division or root."""
    import augmpm

    scene = bench.dam_break_scene(128).to_json()
    c = opcount.count_scene_ops(scene, "naive", warm_up=1, steps=1, engine=augmpm._core.__file__)
    stages = c["stages"]
    assert list(stages) == ["sort", "density", "boundary", "p2g", "grid", "g2p", "step"]
    # The naive step prepares no wall table; P2G and G2P are the step's bulk.
    assert stages["boundary"]["instructions"] < 1
    assert stages["p2g"]["instructions"] + stages["g2p"]["instructions"] > 0.8 * stages["step"]["instructions"]
    assert c["unread_share"] < 1e-3
    assert stages["p2g"]["flops"] >= 9 * 10 and stages["p2g"]["div_sqrt"] >= 1
    assert stages["p2g"]["instructions"] > stages["p2g"]["flops"] / 2


def test_compare_builds_prints_both_builds_counts_and_their_ratios():
    """benches/compare_builds.py --ops: per stage, each build's instructions and flops and the ratio A/B; a stage
    neither ran is left out, and a ratio over nothing is a dash."""
    import importlib.util

    from .conftest import ROOT

    spec = importlib.util.spec_from_file_location("compare_builds", ROOT / "benches" / "compare_builds.py")
    compare = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(compare)

    def counts(p2g: float, g2p_flops: float) -> dict:
        none = {"instructions": 0.0, "flops": 0.0}
        stages = {"boundary": none, "p2g": {"instructions": p2g, "flops": 200.0}, "g2p": {"instructions": 500.0}}
        stages["g2p"]["flops"] = g2p_flops
        return {"warm_up": 3, "steps": 3, "stages": stages}

    lines = compare.format_ops(counts(600.0, 100.0), counts(680.0, 0.0))
    assert lines[0].endswith("steps 4–6 under callgrind")
    rows = {line.split()[0]: line.split()[1:] for line in lines[2:]}
    assert rows.keys() == {"p2g", "g2p"}
    assert rows["p2g"] == ["600.0", "680.0", "0.882", "200.0", "200.0", "1.000"]
    assert rows["g2p"][-1] == "–"
