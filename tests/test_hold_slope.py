"""``myoexo twin hold-slope`` and the hold bound it feeds (:mod:`myoexo.evaluation.bound`)."""

from __future__ import annotations

import json

import pytest

from myoexo.evaluation.bound import HOLD_SLOPE_FIT, hold_bound, hold_slope_nm_per_deg
from myoexo.studies.hold_slope import HoldSlopeSettings, fit_hold_slope


def test_where_the_reference_ends_beyond_the_claim_the_bound_is_its_hold():
    """Level 2: the claim (1 deg) lies inside the reference's stall (6 deg), so a controller
    that meets the claims ends where the reference ends and holds what it holds."""
    bound = hold_bound(99.0, 103.0, 6.0, 1.0, None)
    assert bound is not None
    assert bound["slack_deg"] == 0.0 and bound["hold_slope_nm_per_deg"] == 0.0
    assert bound["least_hold_nm"] == 99.0
    assert bound["peak_reduction_bound_pct"] == pytest.approx(100 * (1 - 99 / 103))


def test_the_claims_slack_lowers_the_least_hold_by_the_slope():
    """Level 3: the claim lets a controller end 0.8 deg further short than the reference, and
    hold up to 0.8 times the slope less; a steeper slope allows more; no slope, no bound."""
    bound = hold_bound(99.5, 105.5, 10.65, 11.45, 2.0)
    assert bound is not None
    assert bound["slack_deg"] == pytest.approx(0.8)
    assert bound["least_hold_nm"] == pytest.approx(99.5 - 1.6)
    assert bound["peak_reduction_bound_pct"] == pytest.approx(100 * (1 - 97.9 / 105.5))
    steeper = hold_bound(99.5, 105.5, 10.65, 11.45, 4.0)
    assert steeper is not None
    assert steeper["peak_reduction_bound_pct"] > bound["peak_reduction_bound_pct"]
    assert hold_bound(99.5, 105.5, 10.65, 11.45, None) is None


def test_a_knee_held_further_short_needs_less_torque():
    """The PID aimed short of the target at level 3 ends further short and holds less: every
    secant is a fall, and the steepest is the bound's."""
    settings = HoldSlopeSettings(subjects=2, levels=(3,), offsets_deg=(10.0, 25.0), perturbed=False)
    level = fit_hold_slope(settings).levels["3"]
    assert level["secants"] >= 2
    assert 0.0 < level["mean_nm_per_deg"] <= level["max_nm_per_deg"] < 10.0
    assert level["end_deg"] > 1.0  # the motor stalls short of the target
    assert 80.0 < level["hold_nm"] < 110.0  # near the motor's 100 Nm


def test_the_slope_is_fitted_data_with_provenance(tmp_path, monkeypatch, capsys):
    """The package holds the fit that ``--write`` writes; without it no level has a slope;
    the evaluation root is refused."""
    from myoexo import cli
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime import fits

    shipped = fits.read_fit(HOLD_SLOPE_FIT)
    assert shipped["provenance"]["twin_version"] == TWIN_VERSION
    assert "hold-slope --seed 3" in shipped["provenance"]["command"]
    assert hold_slope_nm_per_deg(3) == shipped["result"]["levels"]["3"]["max_nm_per_deg"]

    monkeypatch.setattr(fits, "fits_dir", lambda: tmp_path)
    assert hold_slope_nm_per_deg(3) is None
    argv = ["twin", "hold-slope", "--subjects", "1", "--levels", "3", "--write"]
    assert cli.main(argv) == 0
    doc = json.loads((tmp_path / f"{HOLD_SLOPE_FIT}.json").read_text())
    assert doc["provenance"]["root_seed"] == 3 and set(doc["result"]["levels"]) == {"3"}
    assert hold_slope_nm_per_deg(3) == doc["result"]["levels"]["3"]["max_nm_per_deg"]
    assert hold_slope_nm_per_deg(2) is None
    assert cli.main(["twin", "hold-slope", "--seed", "0", "--subjects", "1"]) == 2
    assert "evaluation root" in capsys.readouterr().err
