"""Issue 23 item 6: identify refuses measured rows it cannot use, naming the row, and refuses (or, at exactly as
many data as free parameters, loudly warns about) data too few to determine the free parameters."""

import pytest

from fpm_sim.config import default_config
from fpm_sim.study.identify import DataError, IdentifyOptions, Problem, identify, parameter_set, read_measured_csv
from fpm_sim.study.identify.problem import IdentificationError, IdentificationWarning

HEADER = "x_mm,y_mm,phi_rad,f1_hz,f2_hz,f3_hz\n"


@pytest.mark.parametrize(
    ("rows", "match"),
    [
        ("0,0,0,50,,\n0,nan,0,40,,\n", r"row 3: y_mm"),
        ("0,0,0,50,,\n0,0,inf,40,,\n", r"row 3: phi_rad"),
        ("0,0,0,50,,\n0,0,4,40,,\n", r"row 3: phi_rad: outside"),
        ("0,0,0,50,,\n0,0,-3.2,40,,\n", r"row 3: phi_rad: outside"),
        ("0,0,0,50,inf,\n", r"row 2: f2_hz"),
    ],
)
def test_non_finite_or_out_of_range_rows_are_refused_with_their_row(tmp_path, rows, match):
    p = tmp_path / "m.csv"
    p.write_text(HEADER + rows)
    with pytest.raises(DataError, match=match):
        read_measured_csv(p)


def _problem(tmp_path, rows):
    p = tmp_path / "m.csv"
    p.write_text(HEADER + rows)
    return Problem(parameter_set(default_config(), ["hardware"]), read_measured_csv(p).observations)


def test_an_unreachable_measured_row_is_refused_with_its_row(tmp_path):
    problem = _problem(tmp_path, "0,0,0,50,60,70\n900,0,0,40,,\n")
    with pytest.raises(IdentificationError, match=r"m\.csv: row 3: .*unreachable"):
        identify(problem, options=IdentifyOptions(segments=2, global_method="none", max_nfev=1))


def test_fewer_data_than_free_parameters_are_refused(tmp_path):
    problem = _problem(tmp_path, "0,0,0,50,,\n")  # one frequency, three free masses
    with pytest.raises(IdentificationError, match=r"1 measured value\(s\) for 3 free parameters"):
        identify(problem, options=IdentifyOptions(segments=2, global_method="none", max_nfev=1))


def test_as_many_data_as_free_parameters_warn_that_the_uncertainties_are_unchecked(tmp_path):
    problem = _problem(tmp_path, "0,0,0,50,60,70\n")  # one row, three frequencies, three free masses
    with pytest.warns(IdentificationWarning, match=r"3 measured value\(s\) for 3 free parameters.*no residual"):
        res = identify(problem, options=IdentifyOptions(segments=2, global_method="none", max_nfev=2))
    assert res.dof == 0
