"""The closed forms of the common chains (:mod:`fpm_sim.architecture.closed_forms`) against the general solver.

Truth: the general Newton solver with the closed forms left out (``kinematics._general_unknowns``: the same starts
and steps as before the fast path existed). Both solve to round-off (Newton stops at 1e-11 m and takes one more
chord step; the closed forms are exact formulas), so the coordinates agree to ~1e-11; 1e-9 (the issue's bound)
leaves two orders of margin. The singularity measures are the same function at those coordinates: 1e-9 as well.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from fpm_sim.architecture import TaskPose, load_description, solve_task_pose, task_unknowns
from fpm_sim.architecture import kinematics as kin
from fpm_sim.architecture.description import Description
from fpm_sim.architecture.kinematics import UnreachableTaskPoseError
from fpm_sim.architecture.three_rrr import description_of_3rrr
from fpm_sim.config import default_config

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "architectures"
AGREE = 1e-9  # the bound; both ways close to 1e-11 m or better


def _newton(desc: Description, pose: TaskPose, start: np.ndarray | None = None) -> kin.TaskAssembly:
    """The general solver alone (no closed form)."""
    plan = kin._plan(desc)
    kin._check_reach(desc, pose)
    return kin._assembly(desc, plan.lay, pose, kin._general_unknowns(desc, plan, pose, start), plan.ell)


def _no_newton(*args: object, **kwargs: object) -> None:
    raise AssertionError("Newton ran: the closed form did not serve this pose")


def _machine(name: str) -> Description:
    return description_of_3rrr(default_config()) if name == "3RRR" else load_description(EXAMPLES / f"{name}.toml")


def _row(desc: Description) -> list[TaskPose]:
    """The benchmark's row: 24 poses 5 mm apart through the first check pose."""
    h = desc.check_poses[0] if desc.check_poses else {}
    x, y, phi = h.get("x", 0.0), h.get("y", 0.0), h.get("phi", 0.0)
    return [TaskPose(x - 0.06 + 0.005 * k, y, 0.0, phi) for k in range(24)]


def _assert_same(fast: kin.TaskAssembly, slow: kin.TaskAssembly, desc: Description, atol: float = AGREE) -> None:
    np.testing.assert_allclose(task_unknowns(desc, fast), task_unknowns(desc, slow), rtol=0.0, atol=atol)
    assert fast.closure_residual_m < kin.CLOSURE_TOL_M
    assert abs(fast.singularity_type1 - slow.singularity_type1) < atol
    assert abs(fast.singularity_type2 - slow.singularity_type2) < atol


def _assert_upright(asm: kin.TaskAssembly, desc: Description) -> None:
    """Each chain fixed on the end effector: the relative rotation is the identity (to the closure tolerance over
    the characteristic length, ~1e-10 rad; 1e-9 leaves margin), not a half turn (whose closure rows vanish too)."""
    fixed = [c.name for c in desc.chains if c.end_joint is not None and c.end_joint.type == "fixed"]
    for c in fixed:
        np.testing.assert_allclose(asm.ee_rotation.T @ asm.chains[c].rotations[-1], np.eye(3), atol=1e-9)


@pytest.mark.parametrize("name", ["three_rrr", "three_prr", "3RRR", "five_bar", "serial_arm"])
def test_the_closed_form_serves_and_equals_newton_at_the_check_poses_and_along_a_row(name, monkeypatch):
    """Every check pose and a warm-started row: no Newton step, and Newton's own answer to 1e-9 (the five-bar's and
    the serial arm's free phi among the coordinates), the tool upright on its link."""
    desc = _machine(name)
    poses = [TaskPose(p.get("x", 0.0), p.get("y", 0.0), 0.0, p.get("phi", 0.0)) for p in desc.check_poses]
    start = None
    for pose in poses + _row(desc):
        with monkeypatch.context() as m:
            m.setattr(kin, "_newton", _no_newton)
            fast = solve_task_pose(desc, pose, start=start)
        slow = _newton(desc, pose, start)
        _assert_same(fast, slow, desc)
        _assert_upright(fast, desc)
        start = task_unknowns(desc, fast)


def test_machines_without_a_closed_form_keep_newton():
    """The Delta: a free rotation of a spatial end effector and chains of no pattern (its rods). Newton, as before."""
    assert kin._plan(_machine("delta")).closed is None


def test_a_free_phi_that_turns_an_attachment_point_keeps_newton():
    """The five-bar's tool point moved 10 mm off the end effector's origin: the right chain's attachment point then
    turns with the unknown phi, so no chain's target is known before phi: no closed form, Newton answers upright."""
    desc = _machine("five_bar")
    moved = dataclasses.replace(
        desc, end_effector=dataclasses.replace(desc.end_effector, attachments_m={"p": (0.01, 0.0, 0.0)})
    )
    assert kin._plan(moved).closed is None
    _assert_upright(solve_task_pose(moved, TaskPose(0.0, 0.25)), moved)


@pytest.mark.parametrize(("name", "beyond"), [("five_bar", TaskPose(0.0, 0.5)), ("serial_arm", TaskPose(1.0, 0.0))])
def test_a_pose_beyond_the_reach_of_a_fixed_tool_machine_is_refused(name, beyond):
    """The five-bar's left chain spans 400 mm and (0, 500) mm is 506 mm from its base; the serial arm spans 900 mm:
    no circle intersection, Newton's reach check refuses the pose by name, as before."""
    with pytest.raises(UnreachableTaskPoseError, match="cannot reach"):
        solve_task_pose(_machine(name), beyond)


def test_near_the_3prr_s_workspace_edge_and_beyond_it():
    """Rail 1's link nearly perpendicular to its rail (the platform 10 um inside the edge, y = -0.06 m + 1e-5): the
    two roots nearly meet, the closed form still picks the working mode's and equals Newton. Beyond the edge no
    assembly exists: refused (by Newton's exhausted starts, as before; no reach bound covers a prismatic chain)."""
    desc = _machine("three_prr")
    near = TaskPose(0.0, -0.06 + 1e-5)
    _assert_same(solve_task_pose(desc, near), _newton(desc, near), desc)
    with pytest.raises(UnreachableTaskPoseError):
        solve_task_pose(desc, TaskPose(0.0, -0.06 - 1e-3))


def _reach_edge_x(desc: Description) -> float:
    """The x (y = phi = 0) where the first chain to stretch reaches its links' length: bisection on the distance
    from each base to its attachment point."""
    spans = [sum(lk.length_m for lk in c.links) for c in desc.chains]
    attach = desc.end_effector.attachments_m

    def slack(x: float) -> float:
        return max(
            math.dist((x + attach[str(c.end_joint.at)][0], attach[str(c.end_joint.at)][1]), c.base_position_m[:2]) - s
            for c, s in zip(desc.chains, spans)
            if c.end_joint is not None
        )

    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slack(mid) < 0 else (lo, mid)
    return lo


def test_near_the_3rrr_s_reach_and_beyond_it():
    """A chain stretched to 1 um of its reach (an elbow near straight: a serial singularity, type 1 ~ 0.004). Both
    ways close (the closed form to round-off, Newton to its 1e-11 m), but there a closure of ``r`` metres leaves the
    coordinates uncertain by ``r / (link * type 1)``: they agree to ten times Newton's tolerance over that (~1e-7
    rad; the other working mode would differ by ~0.1 rad). Beyond the reach the pose is refused by name."""
    desc = _machine("three_rrr")
    edge = _reach_edge_x(desc)
    near = TaskPose(edge - 1e-6, 0.0)
    fast, slow = solve_task_pose(desc, near), _newton(desc, near)
    shortest = min(lk.length_m for c in desc.chains for lk in c.links)
    _assert_same(fast, slow, desc, atol=10 * kin.CLOSURE_TOL_M / (shortest * slow.singularity_type1))
    with pytest.raises(UnreachableTaskPoseError, match="cannot reach"):
        solve_task_pose(desc, TaskPose(edge + 1e-4, 0.0))


@pytest.mark.parametrize(
    ("name", "pose"), [("three_rrr", TaskPose(0.01, -0.02, 0.0, 0.05)), ("five_bar", TaskPose(0.0, 0.25))]
)
def test_a_wrong_closed_form_is_caught_by_the_closure_check(name, pose, monkeypatch):
    """Closed forms that are off by 1e-6 rad fail the closure check (1e-11 m): Newton answers, unchanged."""
    from fpm_sim.architecture import closed_forms

    def off(chain):
        solver = closed_forms.chain_solver(chain)
        return None if solver is None else (lambda target: [q + 1e-6 for q in solver(target)])

    monkeypatch.setattr(kin, "chain_solver", off)
    desc = dataclasses.replace(_machine(name))  # a new description: a new plan with the wrong forms
    assert kin._plan(desc).closed is not None
    _assert_same(solve_task_pose(desc, pose), _newton(desc, pose), desc)


@pytest.mark.parametrize("name", ["five_bar", "serial_arm"])
def test_a_tool_fixed_on_a_link_is_assembled_upright_not_half_turned(name):
    """A chain fixed to the end effector closes with the tool along its link, not turned by pi against it: the
    closure's rotation rows vanish at a half turn too, and Newton must not take that root (it did, at all six
    five-bar check poses and one of the serial arm's). The closed form reads phi from the link (upright by
    construction), so Newton is checked on its own (``_newton``), and the served assembly as well."""
    desc = _machine(name)
    for p in desc.check_poses:
        pose = TaskPose(p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0), p.get("phi", 0.0))
        _assert_upright(_newton(desc, pose), desc)
        _assert_upright(solve_task_pose(desc, pose), desc)
