"""BLAS threads are limited around the dense solves only, and never over the user's own setting."""

import pytest
from threadpoolctl import threadpool_info

from fpm_sim.linear.threads import USER_THREAD_VARIABLES, blas_thread_limit, blas_threads


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p.get("user_api") == "blas"]


@pytest.fixture
def clean_env(monkeypatch):
    for name in (*USER_THREAD_VARIABLES, "FPM_SIM_BLAS_THREADS"):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_one_thread_inside_the_block_by_default(clean_env):
    assert blas_thread_limit() == 1
    with blas_threads():
        assert set(_blas_threads()) <= {1}


def test_a_user_setting_is_left_alone(clean_env):
    clean_env.setenv("OPENBLAS_NUM_THREADS", "2")
    assert blas_thread_limit() is None
    before = _blas_threads()
    with blas_threads():
        assert _blas_threads() == before


def test_fpm_sim_blas_threads_sets_the_count(clean_env):
    clean_env.setenv("FPM_SIM_BLAS_THREADS", "3")
    assert blas_thread_limit() == 3
    clean_env.setenv("FPM_SIM_BLAS_THREADS", "0")
    assert blas_thread_limit() == 1  # at least one thread
    clean_env.setenv("FPM_SIM_BLAS_THREADS", "many")
    assert blas_thread_limit() == 1  # not a number: the safe default
