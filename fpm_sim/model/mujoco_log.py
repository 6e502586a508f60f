"""MuJoCo's warnings as Python warnings (:class:`MujocoWarning`), or collected, never written to
``MUJOCO_LOG.TXT``."""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

import mujoco

from fpm_sim.errors import FpmSimWarning

__all__ = [
    "MujocoWarning",
    "mujoco_messages",
    "route_mujoco_warnings",
]


class MujocoWarning(FpmSimWarning):
    """A warning raised inside MuJoCo (e.g. "Nan, Inf or huge value in QACC": the simulation is unstable)."""


def _emit_mujoco_warning(message: str) -> None:
    warnings.warn(f"MuJoCo: {message.strip()}", MujocoWarning, stacklevel=2)


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to Python's ``warnings`` (:class:`MujocoWarning`) instead of ``MUJOCO_LOG.TXT``
    in the working directory and the console (``mujoco.set_mju_user_warning``).

    Called by :func:`~fpm_sim.model.spec.compile_model`, so every fpm-sim model is covered; a handler the caller
    installed first is kept. Inside :func:`mujoco_messages` the messages are collected instead.
    """
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_emit_mujoco_warning)


@contextlib.contextmanager
def mujoco_messages() -> Iterator[list[str]]:
    """Collect MuJoCo's warnings raised inside the ``with`` block into the yielded list (never written to a
    file); the previous handler is restored on exit."""
    previous = mujoco.get_mju_user_warning()
    messages: list[str] = []
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield messages
    finally:
        mujoco.set_mju_user_warning(previous)
