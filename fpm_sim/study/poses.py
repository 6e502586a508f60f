"""The study's 25 test poses and the two open questions of how to read its table.

The study tested the manipulator on a 5 x 5 grid of end-effector positions 50 mm apart, -100 to
100 mm, with the platform turned 0.2 rad "at the poses written (x, 0)" to keep away from a singularity.
Its Table 5 labels each cell ``(row, col)`` under a header "x (mm) y (mm)" without saying unambiguously
which label is x, nor the sign of the rotation. A :class:`TableReading` fixes both:

- ``row_is``: ``"x"`` (row label = x, column label = y) or ``"y"`` (row = y, column = x);
- ``phi_sign``: ``+1`` or ``-1``, the sign of the 0.2 rad rotation.

The rotated cells are those the table writes with a zero second label (``col_mm == 0``, the form
"(x, 0)"), the centre included, whatever the reading: the rotation was applied to the poses as written.
"""

from __future__ import annotations

from dataclasses import dataclass

from fpm_sim.errors import FpmSimError
from fpm_sim.kinematics import Pose
from fpm_sim.study.tables import comsol_table

__all__ = [
    "GRID_MM",
    "READINGS",
    "ROTATION_RAD",
    "StudyPose",
    "TableReading",
    "parse_reading",
    "study_poses",
]

GRID_MM = (-100.0, -50.0, 0.0, 50.0, 100.0)
"""The study's grid coordinates (mm)."""
ROTATION_RAD = 0.2
"""The platform rotation at the poses written (x, 0) (rad), sign per reading."""


@dataclass(frozen=True)
class TableReading:
    """How the table's labels map to the pose (see module docstring)."""

    row_is: str = "x"
    phi_sign: int = 1

    def __post_init__(self) -> None:
        if self.row_is not in ("x", "y"):
            raise FpmSimError(f"TableReading.row_is must be 'x' or 'y', got {self.row_is!r}")
        if self.phi_sign not in (1, -1):
            raise FpmSimError(f"TableReading.phi_sign must be +1 or -1, got {self.phi_sign!r}")

    @property
    def name(self) -> str:
        return f"row={self.row_is},phi={'+' if self.phi_sign > 0 else '-'}{ROTATION_RAD:g}"

    def pose(self, row_mm: float, col_mm: float) -> Pose:
        """The pose of the table cell labelled ``(row_mm, col_mm)``."""
        x_mm, y_mm = (row_mm, col_mm) if self.row_is == "x" else (col_mm, row_mm)
        phi = self.phi_sign * ROTATION_RAD if col_mm == 0.0 else 0.0
        return Pose.from_mm(x_mm, y_mm, phi)


READINGS = tuple(TableReading(r, s) for r in ("x", "y") for s in (1, -1))
"""The four readings of the table."""


def parse_reading(text: str) -> TableReading:
    """``"x+"``, ``"x-"``, ``"y+"`` or ``"y-"`` (row label, rotation sign) -> :class:`TableReading`."""
    t = text.strip().lower()
    if len(t) != 2 or t[0] not in "xy" or t[1] not in "+-":
        raise FpmSimError(
            f"table reading {text!r} not understood; use x+, x-, y+ or y- (rows are x or y, rotation sign)"
        )
    return TableReading(t[0], 1 if t[1] == "+" else -1)


@dataclass(frozen=True)
class StudyPose:
    """One of the 25 study poses: the table's labels, the pose under a reading, COMSOL's value (NaN = none)."""

    row_mm: float
    col_mm: float
    pose: Pose
    comsol_hz: float


def study_poses(reading: TableReading | None = None) -> list[StudyPose]:
    """The 25 study poses under ``reading`` (default: rows are x, +0.2 rad), in the table's order."""
    rd = reading or TableReading()
    return [StudyPose(c.row_mm, c.col_mm, rd.pose(c.row_mm, c.col_mm), c.comsol_hz) for c in comsol_table()]
