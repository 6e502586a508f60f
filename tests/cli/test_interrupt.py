"""Ctrl-C at any moment of ``fpm-sim reproduce`` leaves the output folder absent or complete and consistent.

The run writes into a temporary sibling folder renamed into place on success (fpm_sim.outputs), so an
interrupt before the rename leaves nothing (or the previous run's folder, untouched), after it the whole
new run. Interrupts at 1, 3 and 6 s (the issue's moments; at --segments 3 the run takes about 5 s of CPU,
18 s of wall time on the shared 2-core machine) and near the end of a measured full run, where the files
are being written.
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

# the report and figures, and the bands of the shipped default posterior (fpm_sim/data/default_posterior.nc)
FILES = {"poses.csv", "report.md", "heatmaps.png", "subsystems.png", "bands.nc", "bands.csv", "bands.png"}
READING_LINE = {"x+": "row=x,phi=+0.2", "y-": "row=y,phi=-0.2"}


def command(out: Path, reading: str, *extra: str) -> list[str]:
    return [sys.executable, "-m", "fpm_sim.cli.main", "reproduce", "--segments", "3", "--workers", "1",
            "--reading", reading, "--out", str(out), "--json", *extra]


def run_and_interrupt(argv: list[str], after_s: float) -> subprocess.CompletedProcess:
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(after_s)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def check_folder(out: Path) -> str | None:
    """``None`` if ``out`` is absent, else the reading of the complete, self-consistent run it holds."""
    if not out.exists():
        return None
    assert {p.name for p in out.iterdir()} == FILES, sorted(p.name for p in out.iterdir())
    report = (out / "report.md").read_text()
    (reading,) = [r for r, line in READING_LINE.items() if f"Table reading: **{line}**" in report]
    with open(out / "poses.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 25
    # the report's pose table shows the CSV's own poses and first frequencies (2 decimals)
    poses_table = report.split("| row (mm) | col (mm) |", 1)[1].split("\n\n", 1)[0]  # the 25-pose table only
    table = re.findall(
        r"^\| (-?\d+) \| (-?\d+) \| (-?[\d.]+) \| (-?[\d.]+) \| [+-][\d.]+ \| ([\d.]+) \|", poses_table, re.M
    )
    assert len(table) == 25
    for row, (r_mm, c_mm, x_mm, y_mm, f1) in zip(rows, table):
        assert float(row["row_mm"]) == float(r_mm)
        assert float(row["col_mm"]) == float(c_mm)
        assert float(row["x_mm"]) == pytest.approx(float(x_mm))
        assert float(row["y_mm"]) == pytest.approx(float(y_mm))
        assert f"{float(row['f1_hz']):.2f}" == f1
    return reading


def check_interrupted(res: subprocess.CompletedProcess) -> None:
    if res.returncode == 0:  # finished before the signal: fine, the folder must then be complete
        return
    # 130, or killed by SIGINT (-2) when the interrupt landed inside an extension's own eval during the
    # imports (CPython then re-raises the signal at exit); a shell shows 130 for both
    assert res.returncode in (130, -signal.SIGINT), res.stderr
    assert "Traceback" not in res.stderr
    if res.returncode == 130:  # one line says so; one-line warnings of the run may precede or follow it
        lines = [ln for ln in res.stderr.strip().splitlines() if not ln.startswith("warning:")]
        assert lines, res.stderr
        assert lines[-1].startswith("interrupted"), res.stderr


@pytest.mark.slow
def test_interrupted_reproduce_leaves_nothing_or_a_complete_run(tmp_path):
    first = tmp_path / "first"
    t0 = time.perf_counter()
    done = subprocess.run(command(first, "x+"), capture_output=True, text=True)
    full_s = time.perf_counter() - t0
    assert done.returncode == 0, done.stderr
    assert check_folder(first) == "x+"
    # a new folder, interrupted at several moments: absent or complete
    for k, after_s in enumerate((1.0, 3.0, 6.0, 0.9 * full_s)):
        out = tmp_path / f"new{k}"
        res = run_and_interrupt(command(out, "x+"), after_s)
        check_interrupted(res)
        reading = check_folder(out)
        assert reading in (None, "x+")
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary folder left behind"
    # replacing another run's folder: the old run (x+) or the whole new one (y-), never a mix
    for after_s in (3.0, 0.9 * full_s):
        res = run_and_interrupt(command(first, "y-", "--overwrite"), after_s)
        check_interrupted(res)
        assert check_folder(first) in ("x+", "y-")
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temporary folder left behind"


def test_existing_folder_of_another_run_is_refused(tmp_path, capsys):
    from fpm_sim.cli.main import main

    out = tmp_path / "r"
    out.mkdir()
    (out / "report.md").write_text("another run\n")
    assert main(["reproduce", "--segments", "3", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err
    assert "--out" in err
    assert (out / "report.md").read_text() == "another run\n"


HALF_BUILT = """
import sys
from fpm_sim.cli import main as cli


class HalfBuilt:  # as h5netcdf's File when Ctrl-C lands in its __init__: its __del__ fails
    def __init__(self):
        raise KeyboardInterrupt

    def __del__(self):
        raise AttributeError("'File' object has no attribute '_closed'")


class Parser:
    def parse_args(self, argv):
        import argparse
        return argparse.Namespace(func=lambda args: HalfBuilt(), command="reproduce")


cli.build_parser = Parser
sys.exit(cli.main([]))
"""


def test_ctrl_c_inside_a_library_constructor_is_still_one_line():
    """The failure CI saw (an interrupt inside h5netcdf's File.__init__, whose __del__ then printed "Exception
    ignored ... Traceback"), made deterministic: the one "interrupted" line and 130, nothing else."""
    res = subprocess.run([sys.executable, "-c", HALF_BUILT], capture_output=True, text=True, timeout=120)
    assert res.returncode == 130, res.stderr
    assert res.stderr.strip().splitlines() == ["interrupted (Ctrl-C); unfinished outputs were not written"], res.stderr


def test_ctrl_c_during_identify_is_one_line_and_130(tmp_path):
    """Ctrl-C as a terminal sends it (to the whole process group) while differential evolution runs on a pool of
    worker processes: exit 130, the one "interrupted" line, no worker's traceback, no output folder (issue 32)."""
    from importlib.resources import files

    measured = files("fpm_sim.data").joinpath("measured_table4_train.csv")
    out = tmp_path / "id"
    argv = [sys.executable, "-m", "fpm_sim.cli.main", "identify", "--measured", f"{measured},reading=x+", "--free",
            "section", "--segments", "2", "--workers", "2", "--global", "de", "--out", str(out)]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        for line in proc.stdout:  # the workers are busy once a generation is reported
            if "differential evolution: generation" in line:
                break
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert [ln for ln in err.strip().splitlines() if not ln.startswith("warning:")] == [
        "interrupted (Ctrl-C); unfinished outputs were not written"
    ], err
    assert not out.exists()


@pytest.mark.slow  # ~30-90 s on the shared machine: the first of the 8 (class, seed) runs must finish first
def test_ctrl_c_during_calibrate_is_one_line_and_130_and_stops_the_workers(tmp_path):
    """Ctrl-C to the whole process group while the (class, seed) runs of ``calibrate`` occupy a pool of worker
    processes: exit 130, the one "interrupted" line (besides the finished runs' progress lines), no worker's
    traceback, no posterior written, and no process of the group left (issue 31)."""
    from importlib.resources import files

    data = files("fpm_sim.data")
    out = tmp_path / "cal"
    argv = [sys.executable, "-m", "fpm_sim.cli.main", "calibrate", "--measured",
            f"{data.joinpath('measured_table4_train.csv')},reading=x+", "--priors",
            str(data.joinpath("study_priors.toml")), "--live-points", "25", "--walks", "3", "--dlogz", "2",
            "--runs", "2", "--workers", "2", "--out", str(out)]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        # a run has finished: the workers are busy with the next ones (4 classes, one of each cyclic orbit, x 2 runs)
        for line in proc.stderr:
            if "(1/8 runs)" in line:
                break
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        gone = False  # every worker of the group stops (a stopped worker is reaped by init within a few s)
        for _ in range(30):
            try:
                os.killpg(proc.pid, 0)
            except ProcessLookupError:
                gone = True
                break
            time.sleep(0.5)
        assert gone, "a worker process outlived the interrupted command"
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith(("warning:", "  "))]
    assert lines == ["interrupted (Ctrl-C); unfinished outputs were not written"], err
    assert not (out / "posterior.nc").exists()
