"""Shared small fixtures. The whole session runs with BLAS limited as around fpm_sim's own eigen-solves
(fpm_sim.linear.threads: one thread unless the environment sets a count), since tests solve too."""

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from fpm_sim.config import Manipulator, Material, RigConfig, Section, default_config, load_config


@pytest.fixture(scope="session", autouse=True)
def _blas_threads_for_the_session():
    from fpm_sim.linear.threads import blas_threads

    with blas_threads():
        yield


@pytest.fixture(scope="session")
def default_manip() -> Manipulator:
    return default_config()


@pytest.fixture(scope="session")
def steel_bar() -> RigConfig:
    """The ENGINE_NOTES probe bar: steel 10 x 10 x 228 mm."""
    return RigConfig(length_m=0.228, section=Section(0.010, 0.010), material=Material(200e9, 0.3, 7850.0))


SYMMETRIC_CONFIG = Path(__file__).resolve().parent / "data" / "symmetric_3rrr.toml"
REFERENCE_CONFIG = Path(__file__).resolve().parent / "data" / "reference_3rrr.toml"
PREVIOUS_DEFAULT_CONFIG = Path(__file__).resolve().parent / "data" / "previous_default_3rrr.toml"
"""The default as identified in stop 14: masses and section of the tests calibrated on it."""


@pytest.fixture(scope="session")
def reference_manip() -> Manipulator:
    """The embedded default before its issue-12 re-identification: the fixed geometry that the pose-loop and
    backend tests were measured on (their study poses include a known near-singular one), so that
    re-identifying the default does not move them."""
    return load_config(REFERENCE_CONFIG)


@pytest.fixture(scope="session")
def previous_default_manip() -> Manipulator:
    """The embedded default as identified in stop 14 (frozen copy): masses and section of tests calibrated on it."""
    return load_config(PREVIOUS_DEFAULT_CONFIG)


@pytest.fixture(scope="session")
def symmetric_manip() -> Manipulator:
    """A well-conditioned, three-fold symmetric 3RRR (the pre-identification default) for method tests."""
    return load_config(SYMMETRIC_CONFIG)


# --------------------------------------------------------------------------------------------- Dask on loopback
# A real cluster for the engine tests (tests/batch, tests/designs): one scheduler and two single-threaded
# workers started as subprocesses on 127.0.0.1, shared by the session and stopped at its end.
START_TIMEOUT_S = 120.0
"""Scheduler and worker start, including the workers' import of fpm_sim/MuJoCo on a loaded 2-core machine."""


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=5)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=10)


@pytest.fixture(scope="session")
def loopback_cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Address (``tcp://127.0.0.1:PORT``) of a scheduler with two single-threaded workers; torn down after."""
    from distributed import Client

    tmp = tmp_path_factory.mktemp("dask")
    sched_file = Path(tmp) / "scheduler.json"
    dask_cli = [sys.executable, "-m", "dask"]
    procs: list[subprocess.Popen] = []
    logs = [open(Path(tmp) / f"{name}.log", "w") for name in ("scheduler", "worker0", "worker1")]
    try:
        procs.append(
            subprocess.Popen(
                [*dask_cli, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                 "--scheduler-file", str(sched_file)],
                stdout=logs[0], stderr=subprocess.STDOUT,
            )
        )  # fmt: skip
        deadline = time.monotonic() + START_TIMEOUT_S
        address = None
        while address is None:
            if time.monotonic() > deadline or procs[0].poll() is not None:
                pytest.fail(f"dask scheduler did not start; log: {Path(tmp) / 'scheduler.log'}")
            try:  # the file appears before it is complete
                address = json.loads(sched_file.read_text())["address"]
            except (FileNotFoundError, ValueError, KeyError):
                time.sleep(0.2)
        for k in (1, 2):
            procs.append(
                subprocess.Popen(
                    [*dask_cli, "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
                     "--host", "127.0.0.1", "--name", f"w{k}"],
                    stdout=logs[k], stderr=subprocess.STDOUT,
                )
            )  # fmt: skip
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT_S)
        yield address
    finally:
        _stop(procs[::-1])
        for fh in logs:
            fh.close()
