"""A described machine exported once with rigid links and its motors as joints, and an imported description of it
(tests/imported: the round trip that task-space poses and moves of imported models are checked by)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.architecture.description import LinkDesc
from fpm_sim.architecture.writer import _value
from fpm_sim.model.general import build_general
from fpm_sim.model.options import ModelOptions


def imported_copy(
    desc: Description, folder: Path, *, coordinates: tuple[str, ...] | None = None, servo: bool = False
) -> Path:
    """``desc`` exported at its first check pose with rigid links and its motors as joints (servo springs, no
    actuator), and an imported description of it: each flexible link's body a beam of its length along x, its
    section and material copied, the motors locked (``locked_joints``; with ``servo``, ``servo_joints``: locked for
    modal analysis, servos in a move, the description's ``[servos]`` copied), the end effector's site posed by
    ``coordinates`` (default: the description's task coordinates)."""
    built = build_general(
        desc, TaskPose.from_coordinates(desc.check_poses[0]), ModelOptions(link_model="rigid"), motors="servo"
    )
    (folder / "m.xml").write_text(built.to_xml())
    m, data = built.model, desc.data or {}
    motors = [m.joint(j).name for j in range(m.njnt) if built.dof_kinds[m.jnt_dofadr[j]] == "motor"]
    head: dict[str, Any] = {
        "kind": "imported",
        "name": f"{desc.name}_imported",
        "model": "m.xml",
        ("servo_joints" if servo else "locked_joints"): motors,
        "materials": data["materials"],
        "sections": data["sections"],
        "damping": {"stiffness_proportional_s": desc.damping_beta_s},
        "end_effector": {"site": built.end_effector_site, "coordinates": list(coordinates or desc.task)},
        "flexible": [
            {
                "body": f"{chain.name}_{e.name}_b0",
                "section": raw["section"],
                "material": raw["material"],
                "start_m": [0.0, 0.0, 0.0],
                "end_m": [e.length_m, 0.0, 0.0],
            }
            for chain, chain_raw in zip(desc.chains, data["chains"], strict=True)
            for e, raw in zip(chain.path, chain_raw["path"], strict=True)
            if isinstance(e, LinkDesc) and e.flexible
        ],
    }
    if servo and "servos" in data:
        head["servos"] = data["servos"]
    if coordinates == ():
        del head["end_effector"]
    (folder / "m.toml").write_text(_toml(head))
    return folder / "m.toml"


def _toml(data: dict[str, Any]) -> str:
    """``data`` as TOML: the values inline, the tables (two deep for materials and sections) under headers."""
    lines = [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for k, v in data.items():
        if isinstance(v, dict):
            nested = all(isinstance(t, dict) and "value" not in t for t in v.values())
            for name, t in v.items() if nested else [("", v)]:
                lines += [f"[{k}.{name}]" if name else f"[{k}]", *(f"{a} = {_value(b)}" for a, b in t.items())]
    return "\n".join(lines) + "\n"
