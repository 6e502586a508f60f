"""The MJCF of a spec at full precision.

MuJoCo's XML writer (``MjSpec.to_xml``, ``mj_saveXML``) prints numbers with ``%g``: six significant digits. Its
only switch to full precision is a private, undocumented C function (``_mjPRIVATE__set_xml_precision``, for
MuJoCo's own tests) whose signature has changed between releases (MuJoCo 3.17's getter crashes when called as the
header declares it), so fpm-sim does not call it. Instead :func:`full_precision_xml` takes the writer's text and
rewrites the numbers of bodies, inertials, joints, geoms, sites and equalities with the spec's own values, printed
with :func:`repr` (the shortest text that reads back to the same double). Each rewritten attribute is first checked
against the writer's six digits (relative 1e-5): an attribute the spec states differently (an angle in degrees, an
alternative orientation) is left as the writer printed it. Solver settings (the timestep, ``solref``, ``solimp``) stay
at six digits: fpm-sim derives them from an eigenvalue estimate whose last digits vary between machines, and the
reference files in ``mjcf/`` must not.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np

__all__ = ["full_precision_xml"]

_Field = str | Callable[[Any], Any]

_FIELDS: dict[str, dict[str, _Field]] = {
    "body": {"pos": "pos", "quat": "quat"},
    "inertial": {
        "pos": "ipos",
        "quat": "iquat",
        "mass": "mass",
        "diaginertia": "inertia",
        "fullinertia": "fullinertia",
    },
    "joint": {
        k: k for k in ("pos", "axis", "ref", "springref", "stiffness", "damping", "armature", "range", "frictionloss")
    },
    "geom": {k: k for k in ("size", "pos", "quat", "fromto", "mass", "density")},
    "site": {k: k for k in ("size", "pos", "quat")},
    "equality": {  # solref and solimp stay at six digits, as the timestep: solver settings, not geometry
        "anchor": lambda e: e.data[:3],
        "relpose": lambda e: e.data[3:10],
        "torquescale": lambda e: e.data[10:11],
    },
}


def _numbers(text: str) -> np.ndarray | None:
    try:
        return np.array([float(v) for v in text.split()])
    except ValueError:
        return None


def _rewrite(element: ET.Element, obj: Any, kind: str) -> None:
    """The numeric attributes of ``element`` from ``obj``'s fields, where they agree with the writer's digits."""
    for attr, fld in _FIELDS[kind].items():
        text = element.get(attr)
        if text is None:
            continue
        written = _numbers(text)
        raw = fld(obj) if callable(fld) else getattr(obj, fld, None)
        if written is None or raw is None:
            continue
        values = np.atleast_1d(np.asarray(raw, dtype=float)).ravel()[: written.size]
        if attr == "quat" and values.size == 4 and np.linalg.norm(values) > 0:
            values = values / np.linalg.norm(values)  # the writer prints the normalised quaternion
        if values.size != written.size or not np.all(np.isfinite(values)):
            continue
        if np.allclose(values, written, rtol=1e-5, atol=1e-12 + 1e-5 * float(np.abs(written).max(initial=0.0))):
            element.set(attr, " ".join(repr(float(v)) for v in values))


def _full_inertia(element: ET.Element, body: Any) -> None:
    """A body stated with a full inertia matrix: the writer prints its principal axes (``quat``, ``diaginertia``,
    computed at six digits); the spec's own six numbers are written instead (``fullinertia``), where they agree."""
    full = np.asarray(body.fullinertia, dtype=float)
    diag, quat = _numbers(element.get("diaginertia", "")), _numbers(element.get("quat", "1 0 0 0"))
    if full.size != 6 or not np.all(np.isfinite(full)) or diag is None or quat is None or diag.size != 3:
        return
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, quat / np.linalg.norm(quat))
    r = rot.reshape(3, 3)
    written = r @ np.diag(diag) @ r.T
    stated = np.array([[full[0], full[3], full[4]], [full[3], full[1], full[5]], [full[4], full[5], full[2]]])
    if np.allclose(written, stated, rtol=0.0, atol=1e-5 * float(np.abs(stated).max(initial=0.0))):
        for attr in ("quat", "diaginertia"):
            element.attrib.pop(attr, None)
        element.set("fullinertia", " ".join(repr(float(v)) for v in full))


def _by_order(items: list[Any], tag: str, counters: dict[str, int]) -> Any:
    i = counters.get(tag, 0)
    counters[tag] = i + 1
    return items[i] if i < len(items) else None


def _walk(element: ET.Element, body: Any, spec: mujoco.MjSpec) -> None:
    counters: dict[str, int] = {}
    lists = {"body": body.bodies, "joint": body.joints, "geom": body.geoms, "site": body.sites}
    finders = {"body": spec.body, "joint": spec.joint, "geom": spec.geom, "site": spec.site}
    for child in element:
        tag = child.tag
        if tag == "inertial":
            _full_inertia(child, body)
            _rewrite(child, body, "inertial")
            continue
        if tag not in lists:
            continue
        obj = _by_order(lists[tag], tag, counters)
        name = child.get("name")
        if name:
            obj = finders[tag](name)
        if obj is None:
            continue
        _rewrite(child, obj, tag)
        if tag == "body":
            _walk(child, obj, spec)


def full_precision_xml(spec: mujoco.MjSpec) -> str:
    """``spec.to_xml()`` with the numbers of bodies, inertials, joints, geoms, sites and equalities at full double
    precision (module docstring)."""
    root = ET.fromstring(spec.to_xml())
    world = root.find("worldbody")
    if world is not None:
        _walk(world, spec.worldbody, spec)
    eq = root.find("equality")
    if eq is not None:
        named = {e.name: e for e in spec.equalities if e.name}
        for element, obj in zip(eq, spec.equalities, strict=False):
            _rewrite(element, named.get(element.get("name") or "", obj), "equality")
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"
