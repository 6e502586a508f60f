"""Start-up of the command line and of ``import fpm_sim`` against the floor ``import mujoco, scipy.linalg``.

(Was ``scripts/benchmark_startup.py``.) Each sample runs in a fresh Python process (asv's ``timeraw_``), so the
imports are cold every time; the parameter is what runs, the floor among them, so one run gives the ratios.
The parser is built without importing MuJoCo or SciPy (issue 10, target 1.3x the floor).
"""

from __future__ import annotations

FLOOR = "import mujoco, scipy.linalg"

_CLI = """
import contextlib, io
from fpm_sim.cli.main import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        rc = main({argv!r})
    except SystemExit as exc:  # argparse's --help exits
        rc = exc.code
assert rc in (0, None), rc
"""

STATEMENTS = {
    "floor: import mujoco, scipy.linalg": FLOOR,
    "import fpm_sim": "import fpm_sim",
    "fpm-sim --help": _CLI.format(argv=["--help"]),
    "fpm-sim config": _CLI.format(argv=["config"]),
}


class Startup:
    """One parametrised benchmark: the parameter is what runs (the floor among them)."""

    params = list(STATEMENTS)
    param_names = ["what"]
    number = 1  # a second run in the same process would find the modules cached
    repeat = (5, 15, 60.0)  # fresh processes: at least 5 samples, at most 15 or 60 s

    def timeraw_startup(self, what: str) -> str:
        """The statement, run once in a fresh interpreter per sample (imports included, interpreter start not)."""
        return STATEMENTS[what]
