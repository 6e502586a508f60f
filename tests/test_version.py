"""One version from one place: ``fpm_sim.__version__`` is the source; the package metadata (pyproject reads it
dynamically) and ``fpm-sim --version`` report the same. .ci/run checks the same three on the installed wheel."""

import importlib.metadata
import tomllib
from pathlib import Path

import pytest

import fpm_sim
from fpm_sim.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def test_pyproject_reads_the_version_from_the_package():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in project["project"], "a second version in pyproject: read it from fpm_sim.__version__"
    assert "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "fpm_sim.__version__"}


def test_cli_package_and_metadata_agree(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"fpm-sim {fpm_sim.__version__}"
    # the installed distribution's metadata (an editable install's is written when it is installed)
    assert importlib.metadata.version("fpm-sim") == fpm_sim.__version__
