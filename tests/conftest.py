"""Shared small fixtures. Importing fpm_sim first keeps BLAS single-threaded (see fpm_sim/__init__)."""

import pytest

import fpm_sim  # noqa: F401
from fpm_sim.config import Manipulator, Material, RigConfig, Section, default_config


@pytest.fixture(scope="session")
def default_manip() -> Manipulator:
    return default_config()


@pytest.fixture(scope="session")
def steel_bar() -> RigConfig:
    """The ENGINE_NOTES probe bar: steel 10 x 10 x 228 mm."""
    return RigConfig(length_m=0.228, section=Section(0.010, 0.010), material=Material(200e9, 0.3, 7850.0))
