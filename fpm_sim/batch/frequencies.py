"""The pose loop's entry point: lowest frequencies at many poses, on a backend chosen by name.

``cpu`` (:mod:`fpm_sim.batch.pose_loop`) re-poses one compiled MuJoCo model per structure and solves the
constrained eigenproblem with SciPy, in chunks on the engine (:mod:`fpm_sim.batch.engine`); ``jax``
(:mod:`fpm_sim.batch.jax_backend`) evaluates MuJoCo's formulas, written in JAX, for all poses at once;
``mjx`` (:mod:`fpm_sim.batch.mjx_backend`) runs MJX's own pipeline (``mjx.put_model`` per pose, ``vmap`` of
``jacfwd`` of its smooth forces). All three solve the same eigenproblem. JAX and MJX are imported only when
their backend is called.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from fpm_sim.batch.engine import EngineOptions
from fpm_sim.batch.pose_loop import PoseFrequencies, cpu_backend, fast_options
from fpm_sim.config import Manipulator
from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.model.options import ModelOptions

__all__ = ["BACKENDS", "first_frequencies", "pose_frequencies", "register_backend"]


def _jax_backend(config: Manipulator, poses: Sequence[Pose], **kwargs: Any) -> PoseFrequencies:
    from fpm_sim.batch.jax_backend import jax_pose_frequencies

    return jax_pose_frequencies(config, poses, **kwargs)


def _mjx_backend(config: Manipulator, poses: Sequence[Pose], **kwargs: Any) -> PoseFrequencies:
    from fpm_sim.batch.mjx_backend import mjx_pose_frequencies

    return mjx_pose_frequencies(config, poses, **kwargs)


Backend = Callable[..., PoseFrequencies]
BACKENDS: dict[str, Backend] = {"cpu": cpu_backend, "jax": _jax_backend, "mjx": _mjx_backend}
"""Pose-loop backends by name; see :func:`register_backend`."""


def register_backend(name: str, fn: Backend) -> None:
    """Make ``fn`` available as ``first_frequencies(..., backend=name)``.

    ``fn(config, poses, *, n_modes, options, workers, progress, desc) -> PoseFrequencies``.
    """
    BACKENDS[name] = fn


def pose_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    backend: str = "cpu",
    n_modes: int = 3,
    options: ModelOptions | None = None,
    workers: int = 1,
    progress: bool = False,
    desc: str = "poses",
    engine: EngineOptions | None = None,
) -> PoseFrequencies:
    """Lowest ``n_modes`` natural frequencies (Hz) at each pose, with status and mode character.

    Parameters
    ----------
    config
        The manipulator.
    poses
        End-effector poses (m, m, rad).
    backend
        Name in :data:`BACKENDS`: ``"cpu"`` (SciPy per pose, ``workers`` processes), ``"jax"`` (MuJoCo's
        formulas in JAX, all poses batched) or ``"mjx"`` (MJX's pipeline, all poses batched); all solve the
        constrained eigenproblem with gravity off and agree to round-off.
    n_modes
        Modes per pose.
    options
        Discretisation (default :func:`fast_options`); gravity is ignored by the ``cpu`` backend's
        solve (it uses spring stiffness only).
    workers
        Processes for the ``cpu`` backend (poses are independent; one runs in this process).
    progress
        Show a tqdm progress bar.
    engine
        Where the ``cpu`` backend runs its chunks (Dask scheduler, chunk store for ``resume``; see
        :class:`fpm_sim.batch.engine.EngineOptions`).
    """
    if backend not in BACKENDS:
        raise FpmSimError(
            "unknown backend", parameter="backend", value=backend, hint=f"available: {', '.join(sorted(BACKENDS))}"
        )
    if n_modes < 1:
        raise FpmSimError("must be >= 1", parameter="n_modes", value=n_modes)
    if workers < 1:
        raise FpmSimError("must be >= 1", parameter="workers", value=workers)
    opts = options or fast_options()
    extra: dict[str, Any] = {}
    if engine is not None:
        if backend != "cpu":
            raise FpmSimError(
                "the engine options (scheduler, resume) need the cpu backend", parameter="backend", value=backend
            )
        extra["engine"] = engine
    return BACKENDS[backend](
        config, poses, n_modes=n_modes, options=opts, workers=workers, progress=progress, desc=desc, **extra
    )


def first_frequencies(
    config: Manipulator,
    poses: Sequence[Pose],
    *,
    backend: str = "cpu",
    n_modes: int = 1,
    options: ModelOptions | None = None,
    workers: int = 1,
    progress: bool = False,
) -> np.ndarray:
    """``(n_poses, n_modes)`` lowest natural frequencies (Hz); NaN where unreachable or singular.

    See :func:`pose_frequencies` for the parameters and the details per pose.
    """
    return pose_frequencies(
        config, poses, backend=backend, n_modes=n_modes, options=options, workers=workers, progress=progress
    ).frequencies_hz
