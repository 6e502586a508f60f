"""Every command's ``--json`` is plain, standard JSON: no NaN/Infinity tokens and no Python repr inside a string."""

import json
import re

import pytest

from fpm_sim.cli.main import main

REPR = re.compile(r"array\(|^<.*>$|<[\w.]+ object|object at 0x|\bPose\(|np\.\w+\(|dtype=|^'.*'$|^\(.*,.*\)$")
"""What a Python repr leaves in a string: ``array([...])``, ``<Figure size ...>``, ``<X object at 0x...>``,
``Pose(x_m=...)``, ``np.float64(1.0)``, a quoted ``'name'``, a tuple ``(1, 2)``."""


def _no_nan(token):
    raise AssertionError(f"non-standard JSON token {token}")


def strings(value, path=""):
    """Every string in a JSON value (keys included), with where it is."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield f"{path}/{k} (key)", k
            yield from strings(v, f"{path}/{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from strings(v, f"{path}/{i}")
    elif isinstance(value, str):
        yield path, value


@pytest.fixture(scope="module")
def poses_csv(tmp_path_factory):
    p = tmp_path_factory.mktemp("poses") / "poses.csv"
    p.write_text("x_mm,y_mm,phi_rad\n0,0,0\n50,-50,0.1\n")
    return p


COMMANDS = {
    "modes": ["modes", "--segments", "4", "--n-modes", "3", "--method", "both"],
    "rig": ["rig", "cantilever", "--segments", "4", "--n-modes", "2"],
    "config": ["config"],
    "reduce": ["reduce", "--segments", "4", "--modes", "3"],
    "frf": ["frf", "--segments", "4", "--f-max-hz", "150", "--df-hz", "1"],
}


@pytest.mark.parametrize("name", [*COMMANDS, "sweep"])
def test_json_output_is_plain_json(name, capsys, tmp_path, poses_csv):
    argv = COMMANDS.get(name) or ["sweep", "--poses", str(poses_csv), "--segments", "4", "--out", str(tmp_path / "s")]
    assert main([*argv, "--json"]) == 0
    out = capsys.readouterr().out
    doc = json.loads(out, parse_constant=_no_nan)
    assert isinstance(doc, dict)
    assert doc
    bad = [(where, s) for where, s in strings(doc) if REPR.search(s)]
    assert not bad, bad[:5]


def test_the_check_sees_a_repr():
    """The pattern catches the reprs it is for (else the test above could not fail)."""
    import numpy as np

    import fpm_sim as fs

    for value in (repr(np.array([1.0])), repr(fs.Pose(0.0, 0.0, 0.0)), repr(object()), repr("StateSpace"), str((1, 2))):
        assert REPR.search(value), value
    for value in ("ok", "near_singular", "fpm-sim 0.1.0", "x+ (row=x, phi=+0.2)", "f1 < 1 %"):
        assert not REPR.search(value), value
