"""Imported models (issue 29, item 6): the import's own time, and a sweep pose of an imported model against the
same machine written natively.

- ``ImportTime``: ``fpm-sim import`` of dm_control's ``manipulator.xml`` (its arm's links flexible, the hand and
  props locked, as docs/import.md) without the CLI: the description text, its parse, the mechanisms found and the
  import report (which compiles the model and builds the flexible one's parts). ``track_import_s`` reports its CPU
  seconds (the target: under 2 s); the floor beside it is MuJoCo reading and compiling the same file once
  (``track_import_over_compile``).
- ``ImportedSweepPerPose``: the five-bar (``examples/architectures/five_bar.toml``) exported with rigid links and its
  motors as joints and imported back with its four links flexible (``tests.helpers.imported_copy.py``), swept over
  ``N_POSES`` task poses along a line (the task-space solve with continuation, then
  :func:`fpm_sim.batch.joint_sweep.sweep_joints`: one compiled model posed at every pose) against the native
  five-bar's :func:`fpm_sim.batch.task_sweep.sweep_task` over the same poses, both at the pose loop's options
  (standard fidelity, inextensible, gravity off, 3 modes). ``track_imported_over_native`` is the ratio of their CPU
  seconds per pose, build included (the target: at most 1.2).

CPU time of this process (``time.process_time``), one BLAS thread, as the pose loops run.
"""

from __future__ import annotations

import os
import tempfile
import time
import warnings
from pathlib import Path

from benchmarks.common import OneBlasThread, warm_imports

ROOT = Path(__file__).resolve().parents[1]
N_POSES = 96


def _manipulator_xml() -> Path:
    import dm_control

    return Path(os.path.dirname(dm_control.__file__)) / "suite" / "manipulator.xml"


class ImportTime:
    """``fpm-sim import`` of dm_control's manipulator, and MuJoCo's compile of it (module docstring)."""

    def setup(self) -> None:
        warm_imports()
        self.tmp = Path(tempfile.mkdtemp())
        self.import_once()  # warm: MuJoCo's first compile of a model pays its own start-up

    def import_once(self) -> None:
        import argparse
        import tomllib

        from fpm_sim.architecture.imported import parse_imported
        from fpm_sim.cli.imported import description_text
        from fpm_sim.model.imported import import_report, mechanism_joints

        out = self.tmp / "manipulator.toml"
        args = argparse.Namespace(
            model=_manipulator_xml(),
            flexible="upper_arm,middle_arm,lower_arm",
            section="tube:30x2mm",
            material="aluminium",
            lock="thumb,thumbtip,finger,fingertip,ball_x,ball_z,ball_y,peg_x,peg_z,peg_y",
            end_site=None,
            task=None,
            servo=None,
        )
        text = description_text(args, out)
        desc = parse_imported(tomllib.loads(text), base_dir=self.tmp)
        mechanism_joints(desc)  # the hand's fingers and the props' slides, as the command finds them
        import_report(desc)

    def time_import(self) -> None:
        self.import_once()

    def track_import_s(self) -> float:
        t = time.process_time()
        self.import_once()
        return time.process_time() - t

    def track_import_over_compile(self) -> float:
        import mujoco

        t = time.process_time()
        mujoco.MjSpec.from_file(str(_manipulator_xml())).compile()
        floor = time.process_time() - t
        return self.track_import_s() / floor


def _line(desc: object, n: int) -> list[object]:
    from fpm_sim.architecture import TaskPose

    home = desc.check_poses[0]  # type: ignore[attr-defined]
    return [TaskPose(home["x"] - 0.06 + 0.12 * k / n, home["y"], 0.0, 0.0) for k in range(n)]


class ImportedSweepPerPose(OneBlasThread):
    """The imported five-bar's sweep against the native one's, per pose (module docstring)."""

    params = [["native", "imported"]]
    param_names = ["machine"]
    timeout = 600

    def setup(self, machine: str) -> None:
        import fpm_sim as fs
        from tests.helpers.imported_copy import imported_copy

        warm_imports()
        self.limit_blas()
        self.desc = fs.load_description(ROOT / "examples" / "architectures" / "five_bar.toml")
        self.imported = fs.load_imported(imported_copy(self.desc, Path(tempfile.mkdtemp())))
        self.poses = _line(self.desc, N_POSES)
        self.opts = fs.ModelOptions(axial=False, gravity=False)
        self.seconds(machine)  # warm

    def seconds(self, machine: str) -> float:
        """CPU seconds per pose of ``machine``'s sweep."""
        from fpm_sim.batch.joint_sweep import sweep_joints
        from fpm_sim.batch.task_sweep import sweep_task
        from fpm_sim.model.imported_pose import joint_poses_of

        t = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if machine == "native":
                sweep_task(self.desc, self.poses, options=self.opts, n_modes=3)
            else:
                sweep_joints(self.imported, joint_poses_of(self.imported, self.poses), options=self.opts, n_modes=3)
        return (time.process_time() - t) / N_POSES

    def time_sweep(self, machine: str) -> None:
        self.seconds(machine)

    def track_imported_over_native(self, machine: str) -> float:
        """Imported seconds per pose over native (the same for both parameters: the comparison is the point)."""
        return self.seconds("imported") / self.seconds("native")
