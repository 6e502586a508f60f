"""The reproduce report states its verdict, what the data leave open, and its resolution; every identified
parameter says whether the data determine it."""

import json
from importlib import resources

import pytest

from fpm_sim.batch.pose_loop import fast_options
from fpm_sim.model.options import ModelOptions, resolution_footer, resolution_text
from fpm_sim.study.reproduce import reproduce_study
from fpm_sim.study.reproduce_report import determination
from fpm_sim.study.tables import STUDY_COMSOL_VS_EXPERIMENT

SEG = 3  # the report's text does not depend on the resolution; its numbers are read from the result itself


@pytest.fixture(scope="module")
def report(default_manip):
    rep = reproduce_study(default_manip, options=fast_options(segments=SEG), subsystems=False, readability=False)
    return rep, rep.markdown()


def test_the_report_opens_with_the_verdict(report):
    rep, md = report
    assert md.index("## Verdict") < md.index("## Subsystem tests") < md.index("## Error statistics")
    verdict = md[md.index("## Verdict") : md.index("## Subsystem tests")]
    sm = rep.stats_vs_measured()
    cv = json.loads(resources.files("fpm_sim.data").joinpath("default_identification.json").read_text())
    cv_pct = cv["summary"]["measured_table4_train.csv"]["cross_validated"]["mean_abs_pct"]
    assert f"{sm['mean_abs_pct']:.2f} % in-sample" in verdict
    assert f"{cv_pct:.2f} % cross-validated" in verdict
    assert f"{STUDY_COMSOL_VS_EXPERIMENT['mean_abs_pct']:g} %" in verdict
    assert f"vs COMSOL ({rep.stats()['n']} poses): mean |err| {rep.stats()['mean_abs_pct']:.2f} %" in verdict
    assert f"{cv_pct / STUDY_COMSOL_VS_EXPERIMENT['mean_abs_pct']:.1f}x worse" in verdict
    assert "leave open" in verdict
    assert "(100, -50), (100, 100), (50, 0)" in verdict  # where the competing optima agree
    assert "no posterior was used" in verdict
    # the terminal says the same
    assert f"{sm['mean_abs_pct']:.2f} % in-sample" in rep.table()
    assert rep.table().splitlines()[-1] == resolution_footer(rep.options)


def test_the_cross_validated_command_is_reproducible_from_a_clone(report):
    _, md = report
    cv = md[md.index("### Cross-validated") :]
    assert "scripts/identify_study.py --out out/identify_study" in cv.split("`fpm-sim identify")[0]


def test_undetermined_parameters_are_flagged(report):
    _, md = report
    section = md[md.index("## Identified parameters") : md.index("## Parameters and their provenance")]
    rows = {line.split("|")[1].strip(): line for line in section.splitlines() if line.startswith("| `")}
    assert "not determined by the data" in rows["`hardware.platform.mass_kg`"]  # 4.428 +- 21.03 kg
    assert "yes (sd 11 %)" in rows["`rig.chain_hinge.mass_kg`"]  # 0.5025 +- 0.0559 kg


def test_determination_thresholds():
    assert determination("identified: x; a.b = 4.428 +- 21.03 kg").startswith("**no")
    assert determination("identified: x; a.b = 0.1599 +- 0.09074 m") == "poorly (sd 57 %)"
    assert determination("identified: x; a.b = -0.2 +- 0.01 m") == "yes (sd 5 %)"
    assert determination("identified: x; a.b = -59.78 +- 31.28 deg") == "poorly (sd 31.28 deg)"
    assert determination("study: stated") == "-"


def test_a_description_without_cross_validation_says_so(default_manip):
    other = default_manip.replace(name="my robot")
    rep = reproduce_study(other, options=fast_options(segments=SEG), subsystems=False, readability=False)
    assert "in-sample only" in rep.table()
    md = rep.markdown()
    assert "Not assessed for this description" in md
    assert "competing optima spread" not in md


def test_resolution_text_names_preset_axial_and_gravity():
    assert resolution_text({"link_model": "segments", "segments": 12, "fidelity": None}).startswith(
        "12 segments per link (= fidelity standard)"
    )
    assert "(set explicitly)" in resolution_text({"link_model": "segments", "segments": 5, "fidelity": None})
    text = resolution_footer(ModelOptions(segments=8, axial=False, gravity=False))
    assert text.startswith("resolution: 8 segments per link")
    assert text.endswith("; axial springs off (inextensible links), gravity off")
    assert resolution_footer(None) == ""
