"""Shared small fixtures. The whole session runs with BLAS limited as around fpm_sim's own eigen-solves
(fpm_sim.linear.threads: one thread unless the environment sets a count), since tests solve too."""

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


@pytest.fixture(scope="session")
def symmetric_manip() -> Manipulator:
    """A well-conditioned, three-fold symmetric 3RRR (the pre-identification default) for method tests."""
    return load_config(SYMMETRIC_CONFIG)
