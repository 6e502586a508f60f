"""The generated MJCF files checked into ``mjcf/`` (default manipulator at home and the three rigs).

``python scripts/export_reference_mjcf.py`` rewrites them; ``tests/test_reference_mjcf.py`` fails
when they no longer match what the code generates.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from fpm_sim.config import default_config
from fpm_sim.kinematics import Pose
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.rigs import RigSetup, build_rig, rig_piece
from fpm_sim.model.spec import BuiltModel

__all__ = ["REFERENCE_MODELS", "write_reference_mjcf"]


def _rig(name: str, angle_deg: float = 180.0) -> Callable[[], BuiltModel]:
    def make() -> BuiltModel:
        cfg = default_config()
        setup = RigSetup(name, angle_deg=angle_deg)
        return build_rig(setup, rig_piece(cfg), compliance=cfg.compliance)

    return make


REFERENCE_MODELS: dict[str, Callable[[], BuiltModel]] = {
    "manipulator_home.xml": lambda: build_manipulator(default_config(), Pose(0.0, 0.0, 0.0)),
    "rig_free_free.xml": _rig("free-free"),
    "rig_cantilever.xml": _rig("cantilever"),
    "rig_chain_90deg.xml": _rig("chain", 90.0),
}
"""File name -> builder, all with the embedded default configuration and default options."""


def write_reference_mjcf(directory: str | Path) -> list[Path]:
    """Write every reference model's XML into ``directory``; returns the paths."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, make in REFERENCE_MODELS.items():
        path = out / name
        path.write_text(make().to_xml())
        paths.append(path)
    return paths
