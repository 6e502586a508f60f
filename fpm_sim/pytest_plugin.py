"""Opt-in pytest plugin for frequency requirements (NOT registered as a ``pytest11`` entry point).

Load it on purpose, in the designer's ``conftest.py``::

    pytest_plugins = ["fpm_sim.pytest_plugin"]

or on the command line with ``pytest -p fpm_sim.pytest_plugin``. Installing fpm-sim therefore changes nothing
in a project that does not ask for it. It gives:

- options ``--fpm-config FILE`` (ini ``fpm_config``; default: the embedded description) and
  ``--fpm-segments N`` (overrides every requirement's resolution);
- fixtures ``fpm_config`` (the description, session-wide) and ``fpm_sweep`` (an :class:`FpmSweep`: the
  session's shared sweeps, so that ten requirement tests over the same poses run one sweep);
- the marker ``fpm_requirement(name)``: the test covers that requirement (written to the JUnit XML as the
  property ``fpm_requirement``);
- ``assert fpm_sweep.mode(1, poses=...) >= 40.0`` explained on failure (worst pose, mode, margin, resolution);
- collection of ``fpm-requirements*.toml`` files: one test item per requirement, failing with its message.

Importing this module imports neither MuJoCo, JAX, matplotlib nor SciPy (``tests/test_pytest_plugin.py``);
they load when a fixture or item first runs.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from fpm_sim.batch.pose_loop import PoseFrequencies
    from fpm_sim.config import Manipulator
    from fpm_sim.kinematics import Pose
    from fpm_sim.study.requirements import (
        ModeFrequencies,
        Requirement,
        RequirementOutcome,
        RequirementsFile,
        SweepCache,
    )

__all__ = ["FpmSweep", "RequirementItem", "RequirementsFileCollector"]

REQUIREMENTS_GLOB = "fpm-requirements*.toml"
_OPS = {">=": "<=", ">": "<", "<=": ">=", "<": ">"}


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("fpm-sim", "fpm-sim frequency requirements")
    group.addoption(
        "--fpm-config",
        default=None,
        help="description TOML for the fpm_config fixture and the requirements files (default: ini fpm_config, "
        "then the file's settings.config, then the embedded description)",
    )
    group.addoption(
        "--fpm-segments",
        type=int,
        default=None,
        help="resolution per link for every fpm-sim requirement (overrides settings.segments)",
    )
    parser.addini("fpm_config", "description TOML for fpm-sim requirements (relative to the rootdir)", default="")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "fpm_requirement(name): the test checks the fpm-sim requirement `name` (shown in JUnit XML)"
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        for mark in item.iter_markers("fpm_requirement"):
            if mark.args:
                item.user_properties.append(("fpm_requirement", str(mark.args[0])))


# --------------------------------------------------------------------------------------------- session state


class _State:
    """The session's descriptions (by path) and its one :class:`SweepCache`."""

    def __init__(self, config: pytest.Config) -> None:
        self.pytest_config = config
        self._descriptions: dict[str, Manipulator] = {}
        self._cache: SweepCache | None = None
        self.prepared: dict[str, list[Any]] = {}

    @property
    def cache(self) -> SweepCache:
        if self._cache is None:
            from fpm_sim.study.requirements import SweepCache

            self._cache = SweepCache()
        return self._cache

    @property
    def segments(self) -> int | None:
        seg = self.pytest_config.getoption("fpm_segments")
        return None if seg is None else int(seg)

    def config_path(self, fallback: Path | None = None) -> Path | None:
        opt = self.pytest_config.getoption("fpm_config")
        if opt:
            return Path(opt)
        ini = self.pytest_config.getini("fpm_config")
        if ini:
            return Path(self.pytest_config.rootpath) / str(ini)
        return fallback

    def description(self, path: Path | None) -> Manipulator:
        """The 3RRR's description, a described architecture's (``[[chains]]``: fpm_sim.architecture) or an imported
        model's (``kind = "imported"``)."""
        key = str(path) if path else ""
        if key not in self._descriptions:
            from fpm_sim.architecture import is_description_file, load_description
            from fpm_sim.architecture.imported import is_imported_file, load_imported
            from fpm_sim.config import default_config, load_config

            if path and is_imported_file(path):  # posed by its joints: joint-space pose sets (docs/import.md)
                self._descriptions[key] = load_imported(path)  # type: ignore[assignment]
            elif path and is_description_file(path):
                self._descriptions[key] = load_description(path)  # type: ignore[assignment]
            else:
                self._descriptions[key] = load_config(path) if path else default_config()
        return self._descriptions[key]


_STATE_KEY = pytest.StashKey[_State]()


def _state(config: pytest.Config) -> _State:
    if _STATE_KEY not in config.stash:
        config.stash[_STATE_KEY] = _State(config)
    return config.stash[_STATE_KEY]


# --------------------------------------------------------------------------------------------- fixtures


class FpmSweep:
    """The session's sweeps of one description: each (poses, payload, resolution) is computed once.

    Parameters
    ----------
    config
        The description.
    cache
        The session's :class:`fpm_sim.study.requirements.SweepCache` (shared with the collected requirements).
    segments
        Default resolution per link (``--fpm-segments``; None: the shared default fidelity).
    """

    def __init__(self, config: Manipulator, cache: SweepCache, segments: int | None = None) -> None:
        self.config = config
        self.cache = cache
        self.segments = segments

    def _poses(self, poses: Any, grid: Any) -> list[Pose]:
        from fpm_sim.testing import pose_spec_of

        spec, _ = pose_spec_of(poses, grid)
        return list(spec.resolve(self.config, "fpm_sweep"))

    def frequencies(
        self,
        *,
        poses: str | Sequence[Any] | None = None,
        grid: str | dict[str, Any] | None = None,
        payload_kg: float | None = None,
        n_modes: int = 3,
        segments: int | None = None,
    ) -> PoseFrequencies:
        """The lowest ``n_modes`` frequencies at the poses (default: the reachable workspace, 10 mm grid)."""
        from fpm_sim.study.requirements import options_for

        seg = segments if segments is not None else self.segments
        pts = self._poses(poses, grid)
        return self.cache.frequencies(self.config, pts, payload_kg, options_for(seg), n_modes)  # type: ignore[return-value]

    def mode(
        self,
        mode: int = 1,
        *,
        poses: str | Sequence[Any] | None = None,
        grid: str | dict[str, Any] | None = None,
        payload_kg: float | None = None,
        segments: int | None = None,
    ) -> ModeFrequencies:
        """Mode ``mode`` at every pose, comparable with a number: ``assert fpm_sweep.mode(1) >= 40.0``."""
        from fpm_sim.model.options import resolution_label
        from fpm_sim.study.requirements import ModeFrequencies, options_for

        seg = segments if segments is not None else self.segments
        pf = self.frequencies(poses=poses, grid=grid, payload_kg=payload_kg, n_modes=mode, segments=seg)
        label = resolution_label(options_for(seg))
        return ModeFrequencies(mode, pf.poses, pf.frequencies_hz[:, mode - 1], payload_kg, label)

    def check(self, requirement: Requirement) -> RequirementOutcome:
        """Evaluate a requirement (:class:`fpm_sim.study.requirements.Requirement`) on the shared sweeps."""
        import dataclasses

        from fpm_sim.study.requirements import evaluate

        if requirement.segments is None and self.segments is not None:
            requirement = dataclasses.replace(requirement, segments=self.segments)
        return evaluate(requirement, self.config, cache=self.cache)


@pytest.fixture(scope="session")
def fpm_config(pytestconfig: pytest.Config) -> Manipulator:
    """The description of ``--fpm-config`` (or ini ``fpm_config``), else the embedded default."""
    st = _state(pytestconfig)
    return st.description(st.config_path())


@pytest.fixture(scope="session")
def fpm_sweep(pytestconfig: pytest.Config, fpm_config: Manipulator) -> FpmSweep:
    """Session-wide shared sweeps of ``fpm_config`` (see :class:`FpmSweep`)."""
    st = _state(pytestconfig)
    return FpmSweep(fpm_config, st.cache, st.segments)


# --------------------------------------------------------------------------------------------- assertions


def pytest_assertrepr_compare(config: pytest.Config, op: str, left: Any, right: Any) -> list[str] | None:
    """Explain a failed ``fpm_sweep.mode(...) >= bound`` (either side): worst pose, mode, margin, resolution."""
    for obj, other, o in ((left, right, op), (right, left, _OPS.get(op))):
        if o in _OPS and type(obj).__name__ == "ModeFrequencies" and isinstance(other, int | float):
            if type(obj).__module__ == "fpm_sim.study.requirements":
                lines: list[str] = obj.explain(o, float(other))
                return lines
    return None


# --------------------------------------------------------------------------------------------- requirements files


class RequirementFailed(AssertionError):
    """A requirement of a collected requirements file is not met (its message says where and by how much)."""


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> pytest.Collector | None:
    if fnmatch.fnmatch(file_path.name, REQUIREMENTS_GLOB):
        return RequirementsFileCollector.from_parent(parent, path=file_path)
    return None


class RequirementsFileCollector(pytest.File):
    """One ``fpm-requirements*.toml``: one :class:`RequirementItem` per ``[[requirement]]``."""

    def collect(self) -> Iterator[RequirementItem]:
        from fpm_sim.study.requirements import load_requirements

        reqs = load_requirements(self.path)
        for r in reqs.requirements:
            yield RequirementItem.from_parent(self, name=r.name, requirement=r, requirements=reqs)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException], style: Any = None) -> Any:
        from fpm_sim.errors import FpmSimError

        if isinstance(excinfo.value, FpmSimError):
            return f"error: {excinfo.value}"
        return super().repr_failure(excinfo)


class RequirementItem(pytest.Item):
    """One requirement, evaluated on the session's shared sweeps (the file's requirements prepared together)."""

    def __init__(self, *, requirement: Requirement, requirements: RequirementsFile, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.requirement = requirement
        self.requirements = requirements
        self.add_marker(pytest.mark.fpm_requirement(requirement.name))
        self.user_properties.append(("fpm_requirement", requirement.name))

    def runtest(self) -> None:
        from fpm_sim.study.requirements import effective_requirements, evaluate, prepare_sweeps

        st = _state(self.config)
        config = st.description(st.config_path(self.requirements.config))
        key = str(self.path)
        reqs = effective_requirements(self.requirements, st.segments)
        if key not in st.prepared:  # the first item of the file runs every shared sweep of the file once
            st.prepared[key] = prepare_sweeps(reqs, config, st.cache, keep_errors=True)
        i = [r.name for r in reqs].index(self.requirement.name)
        poses = st.prepared[key][i]
        if isinstance(poses, Exception):
            raise poses
        outcome = evaluate(reqs[i], config, cache=st.cache, poses=poses)
        self.user_properties += [("margin_hz", f"{outcome.margin_hz:.6g}"), ("margin_pct", f"{outcome.margin_pct:.4g}")]
        if not outcome.passed:
            raise RequirementFailed(outcome.message)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException], style: Any = None) -> Any:
        from fpm_sim.errors import FpmSimError

        if isinstance(excinfo.value, RequirementFailed):
            return str(excinfo.value)
        if isinstance(excinfo.value, FpmSimError):
            return f"error: {excinfo.value}"
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[Path, int, str]:
        return self.path, 0, f"fpm-sim requirement: {self.name}"
