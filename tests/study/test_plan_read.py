"""Test planning with a read candidate (issue 30): the first clear peak at an accelerometer point, its mode
unlabelled (the readout model, :mod:`fpm_sim.study.readout`), scored with its mixture likelihood.

Truths: a read certain of mode 1 is the labelled f1 measurement, so it must score exactly as f1 (the same outcomes,
the same weights); and a read that is mode 1 or mode 2 with even odds, the two modes 200 Hz apart (the value says
which mode it was), is f1's measurement on the outcomes that pick mode 1 and mode 2's on the others, so its expected
band is the outcomes' mix of the two exact linear-Gaussian updates (``tests/study/test_plan.py``'s ``_exact``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fpm_sim.cli.main import main
from fpm_sim.kinematics import Pose
from fpm_sim.response import LinkPoint
from fpm_sim.study.plan import Ensemble, Outcomes, PlanError, greedy_plan
from fpm_sim.study.planning import candidates_of, read_point
from tests.study.test_plan import SIGMA, _exact, _linear

S = 4000


def _slots(ens: Ensemble, mode2: np.ndarray, read: np.ndarray | None, used: np.ndarray) -> Ensemble:
    """``ens`` (one labelled slot per candidate) with three slots: f1, ``mode2`` and 500 Hz; read weights ``read``."""
    s, c = ens.cand_hz.shape[:2]
    hz = np.concatenate([ens.cand_hz, mode2[:, :, None], np.full((s, c, 1), 500.0)], axis=2)
    return Ensemble(
        hz, used, ens.cand_shift, ens.cand_disc, SIGMA, ens.target_hz, ens.target_shift, ens.target_disc,
        cand_read_weight=read,
    )  # fmt: skip


@pytest.mark.parametrize("ess_min", [20.0, S + 1.0])  # re-weighting; every outcome the Bayes-linear update
def test_a_read_certain_of_mode_1_scores_exactly_as_f1(ess_min):
    base = _linear()
    c = base.n_candidates
    mode2 = 300.0 + 3.0 * np.random.default_rng(5).standard_normal((S, c))
    f1_used = np.zeros((c, 3), bool)
    f1_used[:, 0] = True
    labelled = _slots(base, mode2, None, f1_used)
    weight = np.zeros((S, c, 3))
    weight[:, :, 0] = 1.0
    read = _slots(base, mode2, weight, np.ones((c, 3), bool))
    assert all(read.is_read(i) for i in range(c))
    assert not any(labelled.is_read(i) for i in range(c))
    # the outcomes' draws and normal numbers are the same (the read's uniform numbers come after them)
    np.testing.assert_array_equal(Outcomes.make(read, 16, 0).z, Outcomes.make(labelled, 16, 0).z)
    a = greedy_plan(labelled, 2, outcomes=16, seed=0, ess_min=ess_min)
    b = greedy_plan(read, 2, outcomes=16, seed=0, ess_min=ess_min)
    assert a.singles == b.singles  # bit for bit: the mixture's log-sum-exp of one certain mode is that mode's term
    assert a.steps == b.steps
    assert (b.singles[0].collapsed > 0) == (ess_min > S)


def test_an_even_odds_read_of_two_informative_modes_is_worth_less_than_labelled_f1():
    """Candidate 0 reads mode 1 (``100 + theta_0``) or mode 2 (``300 + 3 theta_1``: the same 1 Hz-per-sd
    information at 1 % noise, on the other parameter) with even odds; candidate 1 is the labelled f1 there."""
    base = _linear(a=np.array([[1.0, 0.0], [1.0, 0.0]]))
    th1 = _linear(a=np.array([[0.0, 1.0]])).cand_hz[:, 0, 0] - 100.0  # the same draws' theta_1
    mode2 = np.stack([300.0 + 3.0 * th1, np.full(S, 400.0)], axis=1)
    weight = np.full((S, 2, 3), np.nan)
    weight[:, 0] = [0.5, 0.5, 0.0]
    used = np.array([[True, True, False], [True, False, False]])
    ens = _slots(base, mode2, weight, used)
    g = greedy_plan(ens, 1, outcomes=64, seed=0)
    read, f1 = g.singles
    # the outcomes that picked mode 2 (their uniform number above the cumulative 0.5)
    frac2 = float(np.mean(Outcomes.make(ens, 64, 0).pick[:, 0] > 0.5))
    truth = (1.0 - frac2) * _exact(np.array([1.0, 0.0])) + frac2 * _exact(np.array([0.0, 1.0]))
    # 3 %: test_plan.py's bound for 4000 draws and 64 outcomes (the sample's band ~ 1 %, the weighted quantiles
    # ~ 0.3 %); a mode-1 and a mode-2 reading are 200 Hz apart against a 1-3 Hz sd, so the label is never in doubt
    assert read.spread == pytest.approx(truth, rel=0.03)
    assert f1.spread == pytest.approx(_exact(np.array([1.0, 0.0])), rel=0.03)
    # the gap: half of the outcomes inform theta_1, which the target needs less (exact: 0.0110 against 0.0133)
    assert read.spread > f1.spread + 0.3 * (_exact(np.array([0.0, 1.0])) - _exact(np.array([1.0, 0.0])))
    assert g.steps[0].candidate == 1


def test_read_quantity_syntax():
    assert read_point("read:distal_0@0.5:z") == LinkPoint("distal_0", 0.5, "z")
    assert read_point("read:platform@0:x") == LinkPoint("platform", 0.0, "x")
    assert read_point("f1+f2") is None
    cands = candidates_of([Pose(0.0, 0.0, 0.0)], ["f1", "read:proximal_2@1:normal"])
    assert [c.modes for c in cands[:2]] == [(1,), (1, 2, 3)]
    assert cands[1].point == LinkPoint("proximal_2", 1.0, "normal")
    for bad, needle in [
        ("read:distal_0@0.5", "not read:LINK@POS:AXIS"),
        ("read:distal_0:z", "not read:LINK@POS:AXIS"),
        ("read:distal_7@0.5:z", "unknown link 'distal_7'"),
        ("read:distal_0@0.5:w", "unknown axis 'w'"),
        ("read:platform@0.5:normal", "unknown axis 'normal'"),
        ("read:distal_0@1.5:z", "position '1.5'"),
        ("read:distal_0@half:z", "position 'half'"),
        ("f4", "unknown quantity 'f4'"),
    ]:
        with pytest.raises(PlanError, match="quantities") as exc:
            read_point(bad)
        assert needle in str(exc.value), bad
        assert repr(bad) in str(exc.value)


# ------------------------------------------------------------------------------- the command on the shipped posterior
SMALL = ["--draws", "12", "--outcomes", "8", "--target-step-mm", "150", "--workers", "1"]


def test_plan_tests_command_with_a_read(tmp_path, capsys):
    out = tmp_path / "plan"
    argv = ["plan-tests", *SMALL, "--quantities", "f1,read:distal_0@0.5:z", "--k", "2", "--out", str(out), "--json"]
    assert main(argv) == 0
    payload = json.loads(capsys.readouterr().out)
    assert sorted(p.name for p in out.iterdir()) == ["candidates.csv", "gain_map.png", "plan.csv", "plan.json"]
    singles = payload["singles"]
    assert len(singles) == 50
    assert {s["quantity"] for s in singles} == {"f1", "read:distal_0@0.5:z"}
    assert all(np.isfinite(s["expected_spread"]) for s in singles if s["outcomes"])
    assert payload["spread_now"] - sum(r["gain"] for r in payload["plan"]) == pytest.approx(
        payload["spread_after"], abs=1e-12
    )


@pytest.mark.parametrize(
    ("quantity", "needle"),
    [
        ("read:distal_0@0.5", "--quantities: quantity 'read:distal_0@0.5' is not read:LINK@POS:AXIS"),
        ("read:distal_5@0.5:z", "--quantities: quantity 'read:distal_5@0.5:z': unknown link 'distal_5'"),
        ("read:distal_0@0.5:q", "unknown axis 'q'"),
        ("reed:distal_0@0.5:z", "--quantities: unknown 'reed:distal_0@0.5:z'"),
    ],
)
def test_plan_tests_bad_read_is_one_error_line(tmp_path, capsys, quantity, needle):
    out = tmp_path / "plan"
    assert main(["plan-tests", *SMALL, "--quantities", f"f1,{quantity}", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error:")
    assert needle in err[0], err
    assert not out.exists()
