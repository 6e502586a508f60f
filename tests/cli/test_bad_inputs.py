"""A kept battery of bad command-line inputs, run in-process through ``fpm_sim.cli.main.main``.

Every case must end with exit code 2, no traceback, and a message that names the offending parameter
(either its flag spelling ``--n-modes`` or its field spelling ``n_modes``), within a short time: a bad
input is refused before minutes of computing, never answered with exit 0 and a wrong number.

The assertions are on behaviour only (exit code, absence of "Traceback", the parameter's name in the
output), so they hold whatever the exact wording or the error plumbing of the CLI.
"""

from __future__ import annotations

import contextlib
import io
import re
import signal
import traceback
from pathlib import Path

import pytest

from fpm_sim.cli.main import main

TIME_LIMIT_S = 90
"""A bad input must be refused quickly; a case still running after this computed instead of validating
(the slowest legitimate refusals build a 3-segment model first: a few seconds)."""

S3 = ["--segments", "3"]


# (id, argv, parameter names: a regex, "-" and "_" interchangeable). ``{tmp}`` is replaced by a fresh folder.
CASES: list[tuple[str, list[str], str]] = [
    # modes
    ("modes-n-modes-negative", ["modes", "--n-modes", "-2", *S3], "n-modes"),
    ("modes-n-modes-zero", ["modes", "--n-modes", "0", *S3], "n-modes"),
    ("modes-n-modes-huge", ["modes", "--n-modes", "10000", *S3], "n-modes"),
    ("modes-n-modes-text", ["modes", "--n-modes", "many"], "n-modes"),
    ("modes-segments-zero", ["modes", "--segments", "0"], "segments"),
    ("modes-segments-negative", ["modes", "--segments", "-3"], "segments"),
    ("modes-segments-huge", ["modes", "--segments", "100000"], "segments"),
    ("modes-x-unreachable", ["modes", "--x-mm", "1000", *S3], "x-mm|pose"),
    ("modes-x-nan", ["modes", "--x-mm", "nan", *S3], "x-mm"),
    ("modes-y-inf", ["modes", "--y-mm", "inf", *S3], "y-mm"),
    ("modes-phi-out-of-range", ["modes", "--phi-rad", "100", *S3], "phi-rad"),
    ("modes-phi-nan", ["modes", "--phi-rad", "nan", *S3], "phi-rad"),
    ("modes-timestep-negative", ["modes", "--timestep-s", "-1", *S3], "timestep"),
    ("modes-timestep-unstable", ["modes", "--timestep-s", "1", *S3], "timestep"),
    ("modes-link-model-unknown", ["modes", "--link-model", "bogus", *S3], "link-model"),
    ("modes-method-unknown", ["modes", "--method", "bogus"], "method"),
    ("modes-config-missing", ["modes", "--config", "{tmp}/nowhere.toml"], "config|nowhere"),
    ("modes-config-is-a-folder", ["modes", "--config", "{tmp}"], "config"),
    ("modes-config-not-toml", ["modes", "--config", "{tmp}/bad.toml"], "config|bad.toml"),
    ("modes-config-negative-thickness", ["modes", "--config", "{tmp}/neg.toml"], "thickness"),
    ("modes-x-text", ["modes", "--x-mm", "abc"], "x-mm"),
    # flex links near the singularity: the equilibrium iteration diverged into NaN (was LAPACK's SVD traceback)
    ("modes-flex-near-singular", ["modes", "--x-mm", "-100", "--y-mm", "50", "--link-model", "flex", "--fidelity",
                                  "fast", "--n-modes", "2"], "equilibrium"),
    # subsystem rigs
    ("rig-length-negative", ["rig", "cantilever", "--length-mm", "-1000", *S3], "length"),
    ("rig-thickness-zero", ["rig", "cantilever", "--thickness-mm", "0", *S3], "thickness"),
    ("rig-chain-angle", ["rig", "chain", "--angle-deg", "5", *S3], "angle-deg"),
    ("rig-young-negative", ["rig", "free-free", "--young-pa", "-5", *S3], "young"),
    ("rig-poisson", ["rig", "cantilever", "--poisson", "0.7", *S3], "poisson"),
    ("rig-density-zero", ["rig", "cantilever", "--density-kg-m3", "0", *S3], "density"),
    ("rig-clamped-too-long", ["rig", "cantilever", "--clamped-length-mm", "1000", *S3], "clamped"),
    ("rig-n-modes-zero", ["rig", "cantilever", "--n-modes", "0", *S3], "n-modes"),
    ("rig-unknown", ["rig", "bogus"], "rig|bogus"),
    # rollout
    ("rollout-force-1e9", ["rollout", "--force-x-n", "1e9", "--duration-s", "0.002", *S3], "force-x-n"),
    ("rollout-force-inf", ["rollout", "--force-x-n", "inf", "--duration-s", "0.002", *S3], "force-x-n"),
    ("rollout-force-nan", ["rollout", "--force-y-n", "nan", "--duration-s", "0.002", *S3], "force-y-n"),
    ("rollout-duration-negative", ["rollout", "--duration-s", "-1", *S3], "duration"),
    ("rollout-duration-zero", ["rollout", "--duration-s", "0", *S3], "duration"),
    ("rollout-output-step-zero", ["rollout", "--output-step-s", "0", "--duration-s", "0.002", *S3], "output-step"),
    (
        "rollout-load-freq-nan",
        ["rollout", "--force-x-n", "1", "--load-profile", "sine", "--load-freq-hz", "nan", *S3],
        "load-freq",
    ),
    (
        "rollout-motor-torque-locked",
        ["rollout", "--motor-torque-nm", "1", "0", "0", "--duration-s", "0.002", *S3],
        "motor",
    ),
    ("rollout-accel-fraction", ["rollout", "--accel-fraction", "2", "--duration-s", "0.002", *S3], "accel-fraction"),
    ("rollout-out-suffix", ["rollout", "--out", "{tmp}/r.txt", "--duration-s", "0.002", *S3], "out|\\.txt"),
    ("rollout-servo-stiffness", ["rollout", "--motors", "servo", "--servo-stiffness-nm-per-rad", "-1", *S3], "servo"),
    # reduce
    ("reduce-modes-zero", ["reduce", "--modes", "0", *S3], "modes"),
    ("reduce-band-negative", ["reduce", "--band-hz", "-5", *S3], "band-hz"),
    ("reduce-error-bound", ["reduce", "--error-bound", "2", *S3], "error-bound"),
    ("reduce-two-selections", ["reduce", "--modes", "3", "--band-hz", "100", *S3], "modes|band-hz"),
    ("reduce-out-is-a-folder", ["reduce", "--modes", "3", "--out", "{tmp}/taken.mat", *S3], "out|taken"),
    ("reduce-out-suffix", ["reduce", "--modes", "3", "--out", "{tmp}/rom.txt", *S3], "out|\\.txt"),
    # frf
    ("frf-band-reversed", ["frf", "--f-min-hz", "100", "--f-max-hz", "10", *S3], "f-m(in|ax)-hz"),
    ("frf-df-zero", ["frf", "--df-hz", "0", *S3], "df-hz"),
    ("frf-damping-negative", ["frf", "--damping-ratio", "-0.1", *S3], "damping"),
    ("frf-link-unknown", ["frf", "--input-link", "nowhere", *S3], "input-link|nowhere"),
    ("frf-fraction", ["frf", "--input-fraction", "1.5", *S3], "input-fraction"),
    ("frf-n-modes-zero", ["frf", "--n-modes", "0", *S3], "n-modes"),
    # impact
    ("impact-impacts-zero", ["impact", "--impacts", "0", *S3], "error: --impacts: must be an integer >= 1, got 0"),
    ("impact-pulse-negative", ["impact", "--pulse-ms", "-1", *S3], "error: --pulse-ms: must be a positive"),
    ("impact-record-zero", ["impact", "--record-s", "0", *S3], "error: --record-s: must be positive, got 0"),
    ("impact-noise-negative", ["impact", "--noise-m-s2", "-1", *S3], "error: --noise-m-s2: must be >= 0, got -1"),
    ("impact-force-nan", ["impact", "--peak-force-n", "nan", *S3], "error: --peak-force-n: must be positive, got nan"),
    ("impact-implicit-step-too-long", ["impact", "--implicit-step-s", "1e-3", *S3], "implicit-step-s"),
    # study commands
    ("reproduce-reading", ["reproduce", "--reading", "bogus", "--out", "{tmp}/r"], "reading"),
    ("reproduce-thickness-negative", ["reproduce", "--thickness-mm", "-5", "--out", "{tmp}/r"], "thickness"),
    ("reproduce-workers-zero", ["reproduce", "--workers", "0", "--segments", "2", "--out", "{tmp}/r"], "workers"),
    ("sweep-step-zero", ["sweep", "--step-mm", "0", "--out", "{tmp}/s"], "step-mm"),
    ("sweep-backend-unknown", ["sweep", "--backend", "nope", "--out", "{tmp}/s"], "backend"),
    ("transient-force-nan", ["transient", "--force-n", "nan", *S3, "--out", "{tmp}/t"], "force-n"),
    ("transient-duration-negative", ["transient", "--duration-s", "-1", *S3, "--out", "{tmp}/t"], "duration"),
    ("readability-f-max-negative", ["readability", "--f-max-hz", "-1", *S3], "f-max-hz"),
    ("atlas-query-fake-file", ["atlas", "query", "{tmp}/fake.npz"], "atlas|fake.npz"),
    ("atlas-build-one-value", ["atlas", "build", "--x-mm", "nan", "--out", "{tmp}/a.npz", *S3], "x-mm"),
    ("export-mjcf-segments", ["export-mjcf", "manipulator", "--segments", "0", "--out", "{tmp}/m.xml"], "segments"),
]

# Files, outputs and parsers (issue 20): each case also prints exactly one ``error:`` line (its last line) and
# writes nothing. ``{tmp}`` holds the files of :func:`_edge_files`; "afile" is a file in the way of a folder.
M = ["--free", "section", "--out", "{tmp}/id"]
EMA = ["--x-mm", "0", "--y-mm", "0", "--out", "{tmp}/ema"]
VARY = ["--vary", "section.thickness_m=0.01,0.02"]
EDGE_CASES: list[tuple[str, list[str], str]] = [
    # identify --measured
    ("identify-measured-header-only", ["identify", "--measured", "{tmp}/hdr.csv", *M],
     r"hdr\.csv: row 2: only a header"),
    ("identify-measured-inf", ["identify", "--measured", "{tmp}/inf.csv", *M], r"inf\.csv: row 2: f1_hz"),
    ("identify-measured-nan", ["identify", "--measured", "{tmp}/nan.csv", *M], r"nan\.csv: row 2: f1_hz"),
    ("identify-measured-n/a", ["identify", "--measured", "{tmp}/na.csv", *M], r"na\.csv: row 3: f1_hz"),
    ("identify-measured-phi-degrees", ["identify", "--measured", "{tmp}/phi.csv", *M], r"row 2: phi_rad: outside"),
    ("identify-measured-unreachable", ["identify", "--measured", "{tmp}/far.csv", *M],
     r"far\.csv: row 3: .*unreachable"),
    ("identify-too-few-data", ["identify", "--measured", "{tmp}/one.csv", "--free", "hardware", "--out", "{tmp}/id"],
     r"--measured: 1 measured value\(s\) for 3 free parameters"),
    ("identify-measured-missing", ["identify", "--measured", "{tmp}/nowhere.csv", *M], r"--measured: .*nowhere\.csv"),
    ("identify-measured-folder", ["identify", "--measured", "{tmp}", *M], r"--measured: .* is a folder"),
    ("identify-measured-columns", ["identify", "--measured", "{tmp}/cols.csv", *M], r"cols\.csv: columns"),
    ("identify-measured-x-text", ["identify", "--measured", "{tmp}/xtext.csv", *M], r"row 2: x_mm: must be a number"),
    ("identify-measured-negative-f", ["identify", "--measured", "{tmp}/negf.csv", *M], r"row 2: f1_hz: .* > 0"),
    ("identify-measured-mode-kind", ["identify", "--measured", "{tmp}/mode.csv", *M],
     r"row 2: mode: unknown mode kind"),
    ("identify-measured-extra-cells", ["identify", "--measured", "{tmp}/cells.csv", *M], r"cells\.csv: row 2: 5 cells"),
    ("identify-free-unknown", ["identify", "--measured", "{tmp}/ok.csv", "--free", "bogus", "--out", "{tmp}/id"],
     "--free: unknown parameter group"),
    ("identify-out-proc", ["identify", "--measured", "{tmp}/ok.csv", "--free", "section", "--out", "/proc/x/y"],
     "--out: cannot create /proc/x/y"),
    ("identify-out-under-a-file", ["identify", "--measured", "{tmp}/ok.csv", "--free", "section", "--out",
     "{tmp}/afile/id"], "--out: cannot create .*afile is a file"),
    # ema
    ("ema-nan-cell", ["ema", "{tmp}/frf_nan.csv", *EMA], r"frf_nan\.csv: row 3: re_m_s2: must be finite"),
    ("ema-n/a-cell", ["ema", "{tmp}/frf_na.csv", *EMA], r"frf_na\.csv: row 3: im_m_s2: not a number"),
    ("ema-decreasing-frequency", ["ema", "{tmp}/frf_dec.csv", *EMA], r"row 4: freq_hz: .*strictly increasing"),
    ("ema-repeated-frequency", ["ema", "{tmp}/frf_rep.csv", *EMA], r"row 3: freq_hz: .*strictly increasing"),
    ("ema-header-only", ["ema", "{tmp}/frf_hdr.csv", *EMA], r"frf_hdr\.csv: row 1: only a header"),
    ("ema-columns", ["ema", "{tmp}/cols.csv", *EMA], r"cols\.csv: an FRF CSV needs freq_hz"),
    ("ema-missing-file", ["ema", "{tmp}/nowhere.csv", *EMA], r"nowhere\.csv"),
    ("ema-out-proc", ["ema", "{tmp}/frf_dec.csv", "--out", "/proc/x/y"], "--out: cannot create /proc/x/y"),
    # design
    ("design-vary-derived-field", ["design", "--vary", "section.area_m2=1e-4,2e-4", "--out", "{tmp}/d"],
     r"--vary: field 'section\.area_m2': .*derived value.*settable here: thickness_m, height_m"),
    ("design-designs-derived-field", ["design", "--designs", "{tmp}/d_area.csv", "--out", "{tmp}/d"],
     r"--designs: field 'section\.area_m2'.*derived"),
    ("design-designs-unknown-field", ["design", "--designs", "{tmp}/d_typo.csv", "--out", "{tmp}/d"],
     r"--designs: field 'section\.thicknes_m'"),
    ("design-designs-text-cell", ["design", "--designs", "{tmp}/d_text.csv", "--out", "{tmp}/d"],
     r"--designs: .*d_text\.csv: row 3: every cell must be a number"),
    ("design-designs-short-row", ["design", "--designs", "{tmp}/d_short.csv", "--out", "{tmp}/d"],
     r"--designs: .*row 2 has 1 cells for 2 columns"),
    ("design-designs-header-only", ["design", "--designs", "{tmp}/d_hdr.csv", "--out", "{tmp}/d"],
     r"--designs: .*d_hdr\.csv: no rows"),
    ("design-designs-inf", ["design", "--designs", "{tmp}/d_inf.csv", "--out", "{tmp}/d"], r"--designs: .*finite"),
    ("design-resume-over-another-run", ["design", *VARY, "--resume", "--out", "{tmp}/other_run"],
     r"--out .*other_run already holds another run's results; pass --overwrite"),
    ("design-out-under-a-file", ["design", *VARY, "--out", "{tmp}/afile/d"], "--out: cannot create"),
    ("design-poses-phi-degrees", ["design", *VARY, "--poses", "{tmp}/p_phi.csv", "--out", "{tmp}/d"],
     r"--poses: .*p_phi\.csv: row 2: phi_rad: outside"),
    # sweep --poses
    ("sweep-poses-phi-degrees", ["sweep", "--poses", "{tmp}/p_phi.csv", "--out", "{tmp}/s"],
     r"p_phi\.csv: row 2: phi_rad"),
    ("sweep-poses-bom-crlf-phi", ["sweep", "--poses", "{tmp}/p_bom.csv", "--out", "{tmp}/s"],
     r"p_bom\.csv: row 3: phi_rad: outside"),  # the BOM header is read: the error is the row, not a missing column
    ("sweep-poses-text", ["sweep", "--poses", "{tmp}/p_text.csv", "--out", "{tmp}/s"],
     r"row 2: y_mm: must be a number"),
    ("sweep-poses-inf", ["sweep", "--poses", "{tmp}/p_inf.csv", "--out", "{tmp}/s"], r"row 2: x_mm: must be a finite"),
    ("sweep-poses-missing-column", ["sweep", "--poses", "{tmp}/p_cols.csv", "--out", "{tmp}/s"],
     "--poses: .*missing column.*phi_rad"),
    ("sweep-poses-header-only", ["sweep", "--poses", "{tmp}/p_hdr.csv", "--out", "{tmp}/s"], "--poses: .*no rows"),
    ("sweep-out-proc", ["sweep", "--poses", "{tmp}/p_ok.csv", "--out", "/proc/x/y"], "--out: cannot create /proc/x/y"),
    # impact --uff
    ("impact-uff-proc", ["impact", "--uff", "/proc/x/y.uff", *S3], "--uff: cannot create /proc/x/y.uff"),
    ("impact-uff-under-a-file", ["impact", "--uff", "{tmp}/afile/i.uff", *S3], "--uff: cannot create .*afile"),
    ("impact-uff-suffix", ["impact", "--uff", "{tmp}/i.txt", *S3], r"--uff .*i\.txt must end in \.uff or \.unv"),
    ("impact-uff-is-a-folder", ["impact", "--uff", "{tmp}/taken.uff", *S3], "--uff .*taken.uff is a folder"),
    # export-mjcf
    ("export-mjcf-existing-file", ["export-mjcf", "manipulator", "--out", "{tmp}/home.xml", *S3],
     r"--out .*home\.xml already exists; pass --overwrite"),
    ("export-mjcf-proc", ["export-mjcf", "manipulator", "--out", "/proc/x/m.xml", *S3], "--out: cannot create"),
    ("export-mjcf-abbreviation", ["export-mjcf", "manipulator", "--segment", "3"], "unrecognized arguments: --segment"),
    # reduce, frf, atlas build, reproduce
    ("reduce-out-proc", ["reduce", "--modes", "3", "--out", "/proc/x/r.mat", *S3],
     "--out: cannot create /proc/x/r.mat"),
    ("reduce-out-under-a-file", ["reduce", "--modes", "3", "--out", "{tmp}/afile/r.npz", *S3], "--out: cannot create"),
    ("frf-csv-proc", ["frf", "--csv", "/proc/x/f.csv", *S3], "--csv: cannot create /proc/x/f.csv"),
    ("frf-plot-under-a-file", ["frf", "--plot", "{tmp}/afile/f.png", *S3], "--plot: cannot create"),
    ("atlas-build-out-proc", ["atlas", "build", "--out", "/proc/x/a.npz", *S3], "--out: cannot create /proc/x/a.npz"),
    ("atlas-build-abbreviation", ["atlas", "build", "--out", "{tmp}/a.npz", "--mode", "3"],
     "unrecognized arguments: --mode"),
    ("reproduce-out-proc", ["reproduce", "--out", "/proc/x/y"], "--out: cannot create /proc/x/y"),
    ("reproduce-out-is-a-file", ["reproduce", "--out", "{tmp}/afile"], "--out .*afile is an existing file"),
    ("reproduce-thickness-m-abbreviation", ["reproduce", "--thickness-m", "0.01", "--out", "{tmp}/r"],
     "unrecognized arguments: --thickness-m"),
    ("reproduce-thickness-zero", ["reproduce", "--thickness-mm", "0", "--out", "{tmp}/r"],
     "--thickness-mm: must be a positive finite number, got 0 mm"),
    # binary garbage given for every kind of input file (issue 32): one line naming the option, what the file is not
    ("garbage-config", ["modes", "--config", "{tmp}/g.toml", *S3],
     r"^error: --config: .*g\.toml is not a TOML file: binary"),
    ("garbage-config-sweep", ["sweep", "--config", "{tmp}/g.toml", "--out", "{tmp}/s"],
     r"^error: --config: .*g\.toml is not a TOML file: binary"),
    ("garbage-sweep-poses", ["sweep", "--poses", "{tmp}/g.csv", "--out", "{tmp}/s"],
     r"^error: --poses: .*g\.csv is not a CSV file: binary"),
    ("garbage-sweep-poses-nul", ["sweep", "--poses", "{tmp}/nul.csv", "--out", "{tmp}/s"],
     r"^error: --poses: .*nul\.csv is not a CSV file: binary \(a NUL byte"),
    ("garbage-design-poses", ["design", *VARY, "--poses", "{tmp}/g.csv", "--out", "{tmp}/d"],
     r"^error: --poses: .*g\.csv is not a CSV file: binary"),
    ("garbage-design-designs", ["design", "--designs", "{tmp}/g.csv", "--out", "{tmp}/d"],
     r"^error: --designs: .*g\.csv is not a CSV file: binary"),
    ("garbage-identify-measured", ["identify", "--measured", "{tmp}/g.csv", *M],
     r"^error: --measured: .*g\.csv is not a CSV file: binary"),
    ("garbage-identify-measured-nul", ["identify", "--measured", "{tmp}/nul.csv", *M],
     r"^error: --measured: .*nul\.csv is not a CSV file: binary \(a NUL byte"),
    ("garbage-identify-subsystems", ["identify", "--measured", "{tmp}/ok.csv", "--subsystems", "{tmp}/g.csv", *M],
     r"^error: --subsystems: .*g\.csv is not a CSV file: binary"),
    ("garbage-identify-workspace", ["identify", "--measured", "{tmp}/ok.csv", "--workspace", "{tmp}/g.csv", *M],
     r"^error: --workspace: .*g\.csv is not a CSV file: binary"),
    ("garbage-calibrate-measured", ["calibrate", "--priors", "{tmp}/g.toml", "--measured", "{tmp}/g.csv", "--out",
     "{tmp}/c"], r"^error: --measured: .*g\.csv is not a CSV file: binary"),
    ("garbage-calibrate-priors", ["calibrate", "--priors", "{tmp}/g.toml", "--measured", "{tmp}/ok.csv", "--out",
     "{tmp}/c", "--free", "section"], r"^error: --priors: .*g\.toml is not a TOML file: binary"),
    ("garbage-requirements", ["check", "{tmp}/g.toml"], r"^error: .*g\.toml is not a requirements TOML file: binary"),
    ("garbage-modes-posterior", ["modes", "--posterior", "{tmp}/g.nc"],
     r"^error: --posterior: .*g\.nc: not an ArviZ InferenceData netCDF file"),
    ("garbage-reproduce-posterior", ["reproduce", "--posterior", "{tmp}/g.nc", "--out", "{tmp}/r"],
     r"^error: --posterior: .*g\.nc: not an ArviZ InferenceData netCDF file"),
    ("garbage-ema-uff", ["ema", "{tmp}/g.uff", *EMA], r"^error: files: .*g\.uff is not a Universal File: no data set"),
    ("garbage-ema-csv", ["ema", "{tmp}/g.csv", *EMA], r"^error: files: .*g\.csv is not a CSV file: binary"),
    ("garbage-move-path-csv", ["move", "--path-csv", "{tmp}/g.csv", *S3],
     r"^error: --path-csv: .*g\.csv is not a CSV file: binary"),
    ("garbage-atlas", ["atlas", "query", "{tmp}/g.npz"], r"^error: .*g\.npz' is not a readable atlas file"),
]  # fmt: skip

XFAIL: dict[str, str] = {}
"""Cases expected to fail, with the reason (none at present)."""


class _TimedOut(Exception):
    pass


def _run(argv: list[str]) -> tuple[int | None, str]:
    """``(exit code, stdout + stderr)``; an escaping exception is a traceback (exit code None)."""
    out, err = io.StringIO(), io.StringIO()

    def alarm(signum, frame):
        raise _TimedOut

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(TIME_LIMIT_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as e:
                code = e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
            except _TimedOut:
                return None, f"still running after {TIME_LIMIT_S} s: computed instead of refusing"
            except BaseException:  # a traceback is what the battery looks for
                return None, "Traceback (most recent call last):\n" + traceback.format_exc()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    return (0 if code is None else int(code)), out.getvalue() + err.getvalue()


def _files(tmp: Path) -> None:
    from importlib.resources import files

    (tmp / "bad.toml").write_text("this is [not toml")
    default = files("fpm_sim.data").joinpath("default_3rrr.toml").read_text()
    neg = re.sub(r"(thickness_m = \{ value = )(\d)", r"\1-\2", default, count=1)  # the first link thickness, negated
    assert neg != default
    (tmp / "neg.toml").write_text(neg)
    (tmp / "fake.npz").write_bytes(b"not a zip archive")
    (tmp / "taken.mat").mkdir()  # a folder in the way of an output file


@pytest.mark.parametrize(("argv", "names"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_exits_2_naming_the_parameter(argv, names, tmp_path, monkeypatch, request):
    if request.node.callspec.id in XFAIL:
        request.applymarker(pytest.mark.xfail(reason=XFAIL[request.node.callspec.id], strict=False))
    monkeypatch.chdir(tmp_path)  # nothing may land in the caller's folder (e.g. MUJOCO_LOG.TXT)
    _files(tmp_path)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, text = _run(argv)
    assert "Traceback" not in text, text[-3000:]
    assert code == 2, f"exit {code}: {text[-2000:]}"
    pattern = "|".join(n.replace("-", "[-_ ]") for n in names.split("|"))
    assert re.search(pattern, text, re.IGNORECASE), f"no parameter name /{pattern}/ in: {text[-2000:]}"
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def _edge_files(tmp: Path) -> None:
    header = "x_mm,y_mm,phi_rad,f1_hz\n"
    frf = "freq_hz,re_m_s2,im_m_s2\n"
    texts = {
        "afile": "a file in the way of a folder",
        "hdr.csv": "# a comment\n" + header,
        "inf.csv": header + "0,0,0,inf\n",
        "nan.csv": header + "0,0,0,nan\n",
        "na.csv": header + "# measured on Monday\n0,0,0,n/a\n",
        "phi.csv": header + "0,0,30,50\n",
        "far.csv": header + "0,0,0,50\n900,0,0,40\n",
        "one.csv": header + "0,0,0,50\n",
        "ok.csv": header + "0,0,0,50\n20,0,0,48\n",
        "cols.csv": "a,b,c\n1,2,3\n",
        "xtext.csv": header + "abc,0,0,50\n",
        "negf.csv": header + "0,0,0,-5\n",
        "mode.csv": "x_mm,y_mm,phi_rad,f1_hz,mode\n0,0,0,50,sideways\n",
        "cells.csv": header + "0,0,0,50,7\n",
        "frf_nan.csv": frf + "1,0.1,0.2\n2,nan,0.1\n",
        "frf_na.csv": frf + "1,0.1,0.2\n2,0.1,n/a\n",
        "frf_dec.csv": frf + "1,0.1,0.2\n3,0.2,0.1\n2,0.2,0.1\n",
        "frf_rep.csv": frf + "1,0.1,0.2\n1,0.2,0.1\n",
        "frf_hdr.csv": frf,
        "d_area.csv": "section.thickness_m,section.area_m2\n0.01,1e-4\n",
        "d_typo.csv": "section.thicknes_m\n0.01\n",
        "d_text.csv": "section.thickness_m\n0.01\nthin\n",
        "d_short.csv": "section.thickness_m,section.height_m\n0.01\n",
        "d_hdr.csv": "section.thickness_m\n",
        "d_inf.csv": "section.thickness_m\ninf\n",
        "p_phi.csv": "x_mm,y_mm,phi_rad\n0,0,30\n",
        "p_text.csv": "x_mm,y_mm,phi_rad\n0,north,0\n",
        "p_inf.csv": "x_mm,y_mm,phi_rad\ninf,0,0\n",
        "p_cols.csv": "x_mm,y_mm\n0,0\n",
        "p_hdr.csv": "x_mm,y_mm,phi_rad\n",
        "p_ok.csv": "x_mm,y_mm,phi_rad\n0,0,0\n",
        "home.xml": "<mujoco/>\n",
    }
    for name, text in texts.items():
        (tmp / name).write_text(text)
    (tmp / "p_bom.csv").write_bytes(b"\xef\xbb\xbfx_mm,y_mm,phi_rad\r\n0,0,0\r\n0,0,10\r\n")
    (tmp / "other_run").mkdir()
    (tmp / "other_run" / "design.csv").write_text("another study's results\n")
    (tmp / "taken.uff").mkdir()
    garbage = bytes((97 * k + 13) % 256 for k in range(2048))  # binary: not UTF-8 from its third byte
    for name in ("g.toml", "g.csv", "g.nc", "g.uff", "g.npz"):
        (tmp / name).write_bytes(garbage)
    (tmp / "nul.csv").write_bytes(b"x_mm,y_mm,phi_rad,f1_hz\n\x00\x00,0,0,50\n")  # UTF-8, but NUL bytes


def _tree(root: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize(("argv", "pattern"), [c[1:] for c in EDGE_CASES], ids=[c[0] for c in EDGE_CASES])
def test_bad_file_or_output_exits_2_with_one_error_line_and_writes_nothing(argv, pattern, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _edge_files(tmp_path)
    before = _tree(tmp_path)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code, text = _run(argv)
    assert "Traceback" not in text, text[-3000:]
    assert code == 2, f"exit {code}: {text[-2000:]}"
    lines = text.strip().splitlines()
    assert [ln for ln in lines if ln.startswith("error:")] == lines[-1:], text[-2000:]
    assert re.search(pattern, lines[-1]), f"/{pattern}/ not in: {lines[-1]}"
    assert _tree(tmp_path) == before  # nothing written, nothing changed


def test_battery_has_at_least_50_cases():
    assert len(EDGE_CASES) >= 40
    assert len({c[0] for c in CASES + EDGE_CASES}) == len(CASES) + len(EDGE_CASES)
    assert len(CASES) >= 50
    assert len({c[0] for c in CASES}) == len(CASES)
