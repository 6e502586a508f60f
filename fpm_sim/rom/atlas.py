"""Modal atlas: modes tracked across poses by the modal assurance criterion (MAC) and reduced models
interpolated between the poses where they were built.

Interpolating raw eigen-solutions is ill-posed: each pose returns its modes sorted by frequency, with
arbitrary signs, and with an arbitrary basis inside (near-)repeated frequencies (the symmetric pose
(0, 0, 0) of the 3-fold symmetric manipulator has exactly repeated pairs). The atlas therefore:

1. **Tracks** the modes of a root (reference) pose through the grid along a breadth-first tree of
   neighbouring poses. At each pose, the ``n_modes`` labelled shapes of its parent are matched to the
   pose's lowest ``n_modes + n_extra`` modes by maximising the total MAC (Hungarian assignment,
   ``scipy.optimize.linear_sum_assignment``), so a label follows its shape through crossings with
   other modes, including modes that come down from above the kept set. MAC between generalised
   shapes: ``|a'b|^2 / (a'a b'b)``; all poses share one coordinate layout (same joints in the same
   order: spring rotations and passive joint angles relative to the pose's assembly).
2. **Aligns** the matched, ordered shapes ``V`` (mass-normalised, ``V' M V = I``) to the parent's
   aligned basis ``P`` by the orthogonal Procrustes rotation ``Q = polar(V' P)``: for well-separated
   modes ``Q`` is the sign flip that makes each shape agree with its parent, plus a small rotation;
   inside a (near-)repeated pair it picks the basis closest to the parent's. ``V Q`` stays
   mass-normalised.
3. Stores per pose, in the aligned basis ``Phi_a = V Q``: the modal stiffness ``Lambda = Q' Omega^2 Q``
   (symmetric; diagonal up to the alignment rotation), the modal damping ``Xi = Phi_a' C Phi_a``, the
   modal input matrix ``Gamma = Phi_a' B_q`` and output matrices ``C_q Phi_a``, ``C_a Phi_a``, and
   the basis-invariant static-correction feedthrough ``D`` (as :func:`fpm_sim.rom.reduction.reduce_model`).
4. **Interpolates** these matrices entrywise between grid poses (multilinear or cubic, on a
   rectilinear grid in ``x``, ``y``, ``phi``; a described architecture's grid is in its task coordinates: ``x``,
   ``y`` and ``phi`` where it sets it, a spatial machine's at one height ``z``, a horizontal slice) and
   diagonalises the interpolated ``Lambda``
   (``Lambda = U diag(omega^2) U'``) to return an ordinary modal :class:`~fpm_sim.rom.reduction.ReducedModel`
   (states = amplitudes of the interpolated mass-normalised modes, sorted by frequency). Interpolating
   the matrices, not the eigenvalues, is what keeps repeated and crossing modes well posed: matrix
   entries vary smoothly where eigenvalues have kinks.

Error estimate: every query carries ``parameters["atlas_query"]["error_estimate"]``, the estimated
worst relative frequency error of the interpolated modes, from leave-one-out at the grid nodes
(:meth:`ModalAtlas.loo_errors`: each interior node's modal stiffness ``Lambda`` predicted by linear
interpolation between its two neighbours along each axis, over twice the grid spacing, and its sorted
frequencies compared with the node's own): the largest over the modes and over the nodes of the
query's cell and their neighbours, divided by 4 (linear interpolation's error grows as the spacing
squared; the query's cell is half the leave-one-out span). Measured on the symmetric manipulator
(3 segments, 6 modes, 18 query poses): 4.3 % estimated against 4.2 % worst actual on a 3 x 3 grid
(100 mm spacing), 1.5 % against 0.7 % on the 5 x 5 paper grid (cubic). Past :data:`ATLAS_ERROR_WARN`
an :class:`AtlasAccuracyWarning` is issued (refine the grid there). Grids with fewer than 3 values on
every axis have no estimate (NaN, and a warning).

Per-label frequencies (``label_freq_hz``, the tracked frequency of each reference mode at each grid
pose, and which sorted mode it is there) are kept for tables and plots. Two diagnostics:
``label_changes`` (a label's own shape changes character between neighbouring poses: its per-label
frequency is unreliable there, which near repeated or veering modes is common and harmless for the
reduced models) and ``weak_links`` (the aligned basis itself turns: the interpolated reduced models are
unreliable there).
"""

from __future__ import annotations

import json
import math
import warnings
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import scipy.interpolate
import scipy.optimize
from tqdm import tqdm

from fpm_sim.architecture import Description, TaskPose
from fpm_sim.architecture.imported import ImportedDescription
from fpm_sim.config import Manipulator
from fpm_sim.config.checks import check_count
from fpm_sim.errors import FpmSimError, FpmSimWarning
from fpm_sim.kinematics import Pose
from fpm_sim.linear.matrices import system_damping_matrix
from fpm_sim.model.general import build_general
from fpm_sim.model.manipulator import build_manipulator
from fpm_sim.model.options import ModelOptions
from fpm_sim.model.spec import BuiltModel
from fpm_sim.outputs import open_for_writing
from fpm_sim.rom.reduction import ModalSystem, ReducedModel, modal_system

__all__ = [
    "ATLAS_ERROR_WARN",
    "BASIS_MAC_WARN",
    "MAC_WARN",
    "Alignment",
    "AtlasAccuracyWarning",
    "AtlasError",
    "ModalAtlas",
    "align_modes",
    "build_atlas",
    "load_atlas",
    "mac_matrix",
    "track_modes",
]

MAC_WARN = 0.5
"""A label whose matched shape has a MAC below this with its parent's changes character there
(``label_changes``): two candidates share the parent's shape about equally, e.g. modes mixing near a
veering. Its per-label frequency is then not to be trusted; the interpolated reduced models are
unaffected as long as the aligned basis stays consistent (``weak_links``)."""
BASIS_MAC_WARN = 0.8
"""An aligned basis vector whose MAC with its parent's is below this means the tracked modal subspace
itself turns between the two poses (``weak_links``): the interpolated reduced models are then poor
between them; refine the grid or track more modes."""


ATLAS_ERROR_WARN = 0.02
"""Estimated relative frequency error (leave-one-out, module docstring) above which a query warns: the
study's interpolation target (2 %)."""


class AtlasError(FpmSimError):
    """Inconsistent atlas options or queries (named in the message)."""


class AtlasAccuracyWarning(FpmSimWarning):
    """The atlas's estimated interpolation error at a query pose exceeds :data:`ATLAS_ERROR_WARN`."""


def mac_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion between the columns of ``a`` ``(n, p)`` and ``b`` ``(n, q)``: ``(p, q)``."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    num = (a.T @ b) ** 2
    den = np.outer(np.sum(a * a, axis=0), np.sum(b * b, axis=0))
    return num / np.where(den > 0, den, 1.0)


@dataclass
class Alignment:
    """One pose's modes matched and aligned to a parent basis (see module docstring).

    Attributes
    ----------
    index
        ``(k,)`` sorted-mode index at this pose of each label.
    mac
        ``(k,)`` MAC of each matched shape with the parent's shape of the same label.
    mac_aligned
        ``(k,)`` MAC of each aligned basis vector with the parent's (after the Procrustes rotation).
    rotation
        ``(k, k)`` Procrustes rotation ``Q``.
    basis
        ``(nv, k)`` aligned mass-normalised shapes ``V Q``.
    """

    index: np.ndarray
    mac: np.ndarray
    rotation: np.ndarray
    basis: np.ndarray
    mac_aligned: np.ndarray


def align_modes(parent_basis: np.ndarray, phi: np.ndarray, *, n_candidates: int | None = None) -> Alignment:
    """Match the columns of ``parent_basis`` to the lowest ``n_candidates`` columns of ``phi`` by MAC and
    align them by the Procrustes rotation (module docstring, steps 1-2)."""
    k = parent_basis.shape[1]
    n_c = phi.shape[1] if n_candidates is None else min(int(n_candidates), phi.shape[1])
    if n_c < k:
        raise AtlasError(f"{n_c} candidate modes cannot match {k} tracked modes; lower n_modes")
    if phi.shape[0] != parent_basis.shape[0]:
        raise AtlasError(
            f"mode shapes of different models ({phi.shape[0]} vs {parent_basis.shape[0]} degrees of freedom): "
            "every pose of an atlas must use the same model options and configuration"
        )
    cand = phi[:, :n_c]
    m = mac_matrix(parent_basis, cand)
    rows, cols = scipy.optimize.linear_sum_assignment(-m)
    index = cols[np.argsort(rows)]
    v = cand[:, index]
    u, _, wt = np.linalg.svd(v.T @ parent_basis)
    q = u @ wt
    basis = v @ q
    aligned = np.sum(basis * parent_basis, axis=0) ** 2 / (
        np.sum(basis * basis, axis=0) * np.sum(parent_basis * parent_basis, axis=0)
    )
    return Alignment(index=index, mac=m[np.arange(k), index], rotation=q, basis=basis, mac_aligned=aligned)


def track_modes(
    systems: Sequence[ModalSystem],
    *,
    n_modes: int,
    n_extra: int = 4,
    parents: Sequence[int] | None = None,
) -> list[Alignment]:
    """Track the lowest ``n_modes`` modes of ``systems[root]`` through ``systems`` (module docstring).

    Parameters
    ----------
    systems
        Modal systems of the same model layout (e.g. along a parameter sweep or over a pose grid).
    n_modes
        Number of labelled modes (the root's lowest).
    n_extra
        Further modes per system that may take a label (modes crossing in from above).
    parents
        ``parents[i]`` is the system that ``i`` is matched to (``-1`` for the root, exactly one); every
        parent must come before its children. Default: a chain ``-1, 0, 1, ...`` (a sweep).

    Returns
    -------
    One :class:`Alignment` per system; the root's is the identity.
    """
    n = len(systems)
    par = list(range(-1, n - 1)) if parents is None else list(parents)
    if len(par) != n or sum(p < 0 for p in par) != 1 or any(p >= i for i, p in enumerate(par)):
        raise AtlasError("parents must list one root (-1) and a parent before each child")
    root = par.index(-1)
    n_all = min(len(s.omega_rad_s) for s in systems)
    if not (1 <= n_modes <= n_all):
        raise AtlasError(f"n_modes must lie in [1, {n_all}], got {n_modes!r}")
    out: list[Alignment | None] = [None] * n
    base = systems[root].phi[:, :n_modes]
    out[root] = Alignment(np.arange(n_modes), np.ones(n_modes), np.eye(n_modes), base.copy(), np.ones(n_modes))
    for i in range(n):
        if i == root:
            continue
        parent = out[par[i]]
        assert parent is not None
        out[i] = align_modes(parent.basis, systems[i].phi, n_candidates=n_modes + n_extra)
    return [a for a in out if a is not None]


# ---------------------------------------------------------------------------------------------
# the atlas


_NODE_KEYS = (
    "lam",
    "xi",
    "gamma",
    "cq_phi",
    "ca_phi",
    "d",
    "basis",
    "qpos",
    "label_freq_hz",
    "label_index",
    "mac",
    "mac_aligned",
)


@dataclass
class ModalAtlas:
    """Reduced models on a rectilinear pose grid in a consistent modal basis (module docstring).

    Node arrays have shape ``grid_shape + item shape`` with ``grid_shape = (len(x_m), len(y_m),
    len(phi_rad))``.
    """

    x_m: np.ndarray
    y_m: np.ndarray
    phi_rad: np.ndarray
    nodes: dict[str, np.ndarray]
    input_names: list[str]
    input_units: list[str]
    output_names: list[str]
    output_units: list[str]
    root: tuple[int, int, int]
    parents: np.ndarray
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return int(self.nodes["lam"].shape[-1])

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        return (len(self.x_m), len(self.y_m), len(self.phi_rad))

    def poses(self) -> list[Pose | TaskPose]:
        """The grid's poses, x slowest: the 3RRR's :class:`Pose`, or a described architecture's :class:`TaskPose`
        (at the atlas's height ``z``)."""
        grid = [(float(x), float(y), float(p)) for x in self.x_m for y in self.y_m for p in self.phi_rad]
        held = self.parameters.get("architecture")
        return [_pose(held, x, y, p) for x, y, p in grid]

    def check_pose(self, pose: Pose | TaskPose) -> None:
        """Refuse a pose of another kind than the atlas's grid, or off its height (:class:`AtlasError`)."""
        held: dict[str, Any] | None = self.parameters.get("architecture")
        if held is None and not isinstance(pose, Pose):
            raise AtlasError(f"the atlas of {self.parameters.get('config')!r} is queried at a fs.Pose (the 3RRR's)")
        if held is None:
            return
        if not isinstance(pose, TaskPose):
            raise AtlasError(f"the atlas of {self.parameters.get('config')!r} is queried at a fs.TaskPose")
        if not math.isclose(pose.z_m, float(held["z_m"]), abs_tol=1e-9):
            raise AtlasError(
                f"the atlas is a slice at z = {float(held['z_m']) * 1e3:g} mm",
                parameter="z_m",
                value=pose.z_m,
                hint="query that height, or build an atlas at this one",
            )

    def _below(self, key: str, threshold: float) -> list[tuple[Pose | TaskPose, int, float]]:
        out = []
        for flat, pose in enumerate(self.poses()):
            idx = np.unravel_index(flat, self.grid_shape)
            mac = self.nodes[key][idx]
            out += [(pose, j, float(mac[j])) for j in range(self.n_modes) if mac[j] < threshold]
        return out

    def label_changes(self, threshold: float = MAC_WARN) -> list[tuple[Pose | TaskPose, int, float]]:
        """Labels whose matched shape has a MAC below ``threshold`` with the parent pose's: (pose, label, MAC)."""
        return self._below("mac", threshold)

    def weak_links(self, threshold: float = BASIS_MAC_WARN) -> list[tuple[Pose | TaskPose, int, float]]:
        """Aligned basis vectors with a MAC below ``threshold`` with the parent pose's: (pose, label, MAC)."""
        return self._below("mac_aligned", threshold)

    def _axes(self) -> tuple[list[np.ndarray], list[int]]:
        axes = [self.x_m, self.y_m, self.phi_rad]
        live = [i for i, a in enumerate(axes) if len(a) > 1]
        return [axes[i] for i in live], live

    def _interp(self, key: str, pose: Pose | TaskPose, method: str) -> np.ndarray:
        values = self.nodes[key]
        axes, live = self._axes()
        point = np.array([pose.x_m, pose.y_m, pose.phi_rad])
        names = ("x_m", "y_m", "phi_rad")
        fixed = [i for i in range(3) if i not in live]
        for i in fixed:
            a = (self.x_m, self.y_m, self.phi_rad)[i]
            if not math.isclose(point[i], float(a[0]), abs_tol=1e-9):
                raise AtlasError(f"the atlas has the single value {names[i]} = {float(a[0]):g}; query that value")
        for ax, i in zip(axes, live):
            lo, hi = float(ax[0]), float(ax[-1])
            if not (lo - 1e-12 <= point[i] <= hi + 1e-12):
                raise AtlasError(f"{names[i]} = {point[i]:g} lies outside the atlas grid [{lo:g}, {hi:g}]")
        if not live:
            return values[0, 0, 0]
        if method == "cubic" and any(len(a) < 4 for a in axes):
            raise AtlasError("cubic interpolation needs at least 4 grid values on every axis; use method='linear'")
        # tensor-product spline interpolation, one axis at a time (separable, so exact at the grid nodes;
        # scipy's RegularGridInterpolator 'cubic' solves its spline system iteratively and is not)
        out = values
        for i in (2, 1, 0):
            ax = (self.x_m, self.y_m, self.phi_rad)[i]
            if len(ax) == 1:
                out = np.take(out, 0, axis=i)
                continue
            k = 3 if method == "cubic" or (method == "auto" and len(ax) >= 4) else 1
            spline = scipy.interpolate.make_interp_spline(ax, out, k=k, axis=i)
            out = spline(point[i])
        return np.asarray(out)

    def loo_errors(self) -> np.ndarray:
        """Leave-one-out relative frequency error at each grid node, ``grid_shape + (n_modes,)`` (module
        docstring); NaN at nodes with no neighbour on both sides along any axis."""
        lam = 0.5 * (self.nodes["lam"] + np.swapaxes(self.nodes["lam"], -1, -2))
        freq = np.sqrt(np.maximum(np.linalg.eigvalsh(lam), 0.0))
        err = np.full(freq.shape, np.nan)
        for axis, values in enumerate((self.x_m, self.y_m, self.phi_rad)):
            for i in range(1, len(values) - 1):
                w = (values[i] - values[i - 1]) / (values[i + 1] - values[i - 1])
                pred = (1 - w) * np.take(lam, i - 1, axis=axis) + w * np.take(lam, i + 1, axis=axis)
                f_pred = np.sqrt(np.maximum(np.linalg.eigvalsh(pred), 0.0))
                f_node = np.take(freq, i, axis=axis)
                e = np.abs(f_pred / np.where(f_node > 0, f_node, np.inf) - 1.0)
                index: list[slice | int] = [slice(None)] * 3
                index[axis] = i
                err[tuple(index)] = np.fmax(err[tuple(index)], e)
        return err

    def error_estimate(self, pose: Pose | TaskPose) -> float:
        """Estimated worst relative frequency error of a query at ``pose`` (module docstring): a quarter of the
        largest leave-one-out error over the modes and the nodes of its grid cell and their neighbours; NaN
        without an estimate."""
        return self._estimate(pose)[0]

    def error_estimate_node(self, pose: Pose | TaskPose) -> tuple[float, float, float] | None:
        """The grid node ``(x_m, y_m, phi_rad)`` whose leave-one-out error sets :meth:`error_estimate` at
        ``pose`` (None without an estimate): a node whose interpolation stencil reaches a near-singular pose
        makes the estimate large even where the query itself interpolates well."""
        return self._estimate(pose)[1]

    def _estimate(self, pose: Pose | TaskPose) -> tuple[float, tuple[float, float, float] | None]:
        err = self.loo_errors()
        window = []
        for values, v in zip((self.x_m, self.y_m, self.phi_rad), (pose.x_m, pose.y_m, pose.phi_rad)):
            hi = int(np.clip(np.searchsorted(values, v), 0, len(values) - 1))
            lo = max(hi - 1, 0)
            window.append(slice(max(lo - 1, 0), min(hi + 2, len(values))))
        block = err[tuple(window)]
        if np.all(np.isnan(block)):
            return math.nan, None
        worst = np.unravel_index(int(np.nanargmax(block)), block.shape)
        node = tuple(
            float(values[w.start + int(k)]) for values, w, k in zip((self.x_m, self.y_m, self.phi_rad), window, worst)
        )
        return float(np.nanmax(block)) / 4.0, (node[0], node[1], node[2])

    def _method(self, method: str) -> str:
        if method not in ("auto", "linear", "cubic"):
            raise AtlasError(f"method must be 'auto', 'linear' or 'cubic', got {method!r}")
        return method

    def query(self, pose: Pose | TaskPose, *, method: str = "auto") -> ReducedModel:
        """The reduced model at ``pose``, interpolated (module docstring, step 4).

        Parameters
        ----------
        method
            ``"linear"`` (multilinear), ``"cubic"`` (needs 4 or more values on each axis) or ``"auto"``
            (cubic along the axes with 4 or more values, linear along the others). Measured on the
            5 x 5 paper grid (3 segments, 6 tracked modes, phi 0): f1..f3 at the 16 cell midpoints
            within 0.73 % (cubic) and 2.4 % (linear) of a direct computation; see
            ``tests/test_modal_atlas.py``.
        """
        method = self._method(method)
        self.check_pose(pose)
        get = {
            k: self._interp(k, pose, method) for k in ("lam", "xi", "gamma", "cq_phi", "ca_phi", "d", "basis", "qpos")
        }
        lam = 0.5 * (get["lam"] + get["lam"].T)
        w2, u = np.linalg.eigh(lam)
        if np.any(w2 <= 0):
            raise AtlasError("the interpolated modal stiffness is not positive definite; refine the atlas grid")
        w = np.sqrt(w2)
        xi = u.T @ (0.5 * (get["xi"] + get["xi"].T)) @ u
        gamma = u.T @ get["gamma"]
        cq = get["cq_phi"] @ u
        ca = get["ca_phi"] @ u
        k = len(w)
        n_in = gamma.shape[1]
        a = np.block([[np.zeros((k, k)), np.eye(k)], [-np.diag(w2), -xi]])
        b = np.vstack([np.zeros((k, n_in)), gamma])
        c = np.vstack([np.hstack([cq, np.zeros_like(cq)]), np.hstack([-ca * w2, -ca @ xi])])
        d = get["d"].copy()
        d[cq.shape[0] :] = ca @ gamma  # acceleration feedthrough of the interpolated modes
        estimate, node = self._estimate(pose)
        if math.isnan(estimate):
            warnings.warn(
                "the atlas has fewer than 3 grid values on every axis: no interpolation error estimate; build it on "
                "a finer grid",
                AtlasAccuracyWarning,
                stacklevel=2,
            )
        elif estimate > ATLAS_ERROR_WARN:
            warnings.warn(
                f"atlas query at {pose.label()}: estimated interpolation error {estimate:.1%} exceeds "
                f"{ATLAS_ERROR_WARN:.0%}; the estimate is the worst leave-one-out error at the neighbouring grid "
                f"nodes, here at the node {_node_label(node)}, whose own neighbours may be near a singularity, so "
                "it can overstate the error at this pose; check it with a direct computation (fpm-sim atlas query "
                "--direct, fpm-sim reduce) or refine the atlas grid around this pose",
                AtlasAccuracyWarning,
                stacklevel=2,
            )
        params = dict(self.parameters)
        params["atlas_query"] = {
            "method": method,
            "pose": asdict(pose),
            "error_estimate": None if math.isnan(estimate) else estimate,
            "error_estimate_node": None if node is None else list(node),
        }
        return ReducedModel(
            a=a,
            b=b,
            c=c,
            d=d,
            input_names=list(self.input_names),
            input_units=list(self.input_units),
            output_names=list(self.output_names),
            output_units=list(self.output_units),
            pose=pose,
            frequencies_hz=w / (2 * np.pi),
            damping_ratios=np.diag(xi) / (2 * w),
            modal_masses=np.ones(k),
            mode_shapes=get["basis"] @ u,
            qpos=get["qpos"],
            static_correction=True,
            parameters=params,
        )

    def label_frequencies(self, pose: Pose | TaskPose, *, method: str = "auto") -> np.ndarray:
        """Tracked frequency (Hz) of each reference mode label at ``pose``, interpolated per label.

        Coarser than :meth:`query` wherever a label changes character between grid poses
        (:meth:`label_changes`).
        """
        return self._interp("label_freq_hz", pose, self._method(method))

    def to_xarray(self) -> Any:
        """Tracked frequencies over the grid poses (:func:`fpm_sim.results.frequencies_dataset`; ``mode`` is the
        tracked label, poses in :meth:`poses` order) with ``mac`` (the label's MAC with its parent pose)."""
        from fpm_sim.results import frequencies_dataset

        poses = self.poses()
        f = self.nodes["label_freq_hz"].reshape(len(poses), self.n_modes)
        return frequencies_dataset(
            f,
            x_mm=[p.x_m * 1e3 for p in poses],
            y_mm=[p.y_m * 1e3 for p in poses],
            phi_rad=[p.phi_rad for p in poses],
            status=np.where(np.isfinite(f).all(axis=1), "ok", "not_computed"),
            data_vars={"mac": (("pose", "mode"), self.nodes["mac"].reshape(len(poses), self.n_modes))},
            attrs={"config": str(self.parameters.get("config", ""))},
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the grid (mm, rad), inputs and outputs, weak links and label changes, parameters."""
        return {
            "x_mm": (self.x_m * 1e3).tolist(),
            "y_mm": (self.y_m * 1e3).tolist(),
            "phi_rad": self.phi_rad.tolist(),
            "n_modes": self.n_modes,
            "root": [
                float(self.x_m[self.root[0]] * 1e3),
                float(self.y_m[self.root[1]] * 1e3),
                float(self.phi_rad[self.root[2]]),
            ],
            "inputs": self.input_names,
            "outputs": self.output_names,
            "weak_links": [
                {"pose_mm": [p.x_m * 1e3, p.y_m * 1e3, p.phi_rad], "label": j + 1, "mac_aligned": m}
                for p, j, m in self.weak_links()
            ],
            "label_changes": [
                {"pose_mm": [p.x_m * 1e3, p.y_m * 1e3, p.phi_rad], "label": j + 1, "mac": m}
                for p, j, m in self.label_changes()
            ],
            "min_mac_aligned": float(self.nodes["mac_aligned"].min()),
            "parameters": self.parameters,
        }

    def table(self) -> str:
        """Tracked frequency of each label at each grid pose, with its sorted position where it moved."""
        k = self.n_modes
        head = f"{'x mm':>7} {'y mm':>7} {'phi':>6}  " + "  ".join(f"{'mode ' + str(j + 1):>13}" for j in range(k))
        lines = [head]
        for flat, pose in enumerate(self.poses()):
            idx = np.unravel_index(flat, self.grid_shape)
            f = self.nodes["label_freq_hz"][idx]
            pos = self.nodes["label_index"][idx]
            cells = []
            for j in range(k):
                tag = f"(#{int(pos[j]) + 1})" if int(pos[j]) != j else ""
                cells.append(f"{f[j]:>8.2f}{tag:>5}")
            lines.append(f"{pose.x_m * 1e3:>7.1f} {pose.y_m * 1e3:>7.1f} {pose.phi_rad:>6.3f}  " + "  ".join(cells))
        return "\n".join(lines)

    def plot(self, ax: Any = None, *, labels: Sequence[int] = (1, 2, 3), phi_index: int = 0, axes: Any = None) -> Any:
        """Tracked frequency (Hz) of the given mode labels (1-based) over the x-y grid at one rotation, with
        the label changes marked; returns the ``Figure``.

        ``ax``: one axes for the first label; ``axes``: one per label; default a new figure.
        """
        import matplotlib.pyplot as plt

        labels = [lab for lab in labels if lab <= self.n_modes]
        if ax is not None:
            axes, labels = [ax], labels[:1]
        elif axes is None:
            fig, axes = plt.subplots(1, len(labels), figsize=(4.2 * len(labels), 3.8), squeeze=False)
            fig.set_layout_engine("constrained")
            axes = axes[0]
        xx, yy = np.meshgrid(self.x_m * 1e3, self.y_m * 1e3, indexing="ij")
        for ax, lab in zip(np.atleast_1d(axes), labels):
            f = self.nodes["label_freq_hz"][:, :, phi_index, lab - 1]
            sc = ax.scatter(xx, yy, c=f, s=160, cmap="viridis")
            weak = self.nodes["mac"][:, :, phi_index, lab - 1] < MAC_WARN
            ax.scatter(xx[weak], yy[weak], marker="x", color="r", s=60)
            ax.set_title(f"mode {lab} (tracked), phi = {self.phi_rad[phi_index]:g} rad", fontsize=9)
            ax.set_xlabel("x (mm)")
            ax.set_ylabel("y (mm)")
            ax.set_aspect("equal")
            ax.figure.colorbar(sc, ax=ax, shrink=0.8, label="tracked frequency (Hz)")
        figure = np.atleast_1d(axes)[0].figure
        figure.suptitle(
            f"red x: the label changes character there (its shape's MAC with the parent pose below {MAC_WARN:g}): "
            "its frequency is unreliable",
            fontsize=9,
        )
        return figure

    def save(self, path: str | Path) -> Path:
        p = Path(path)
        if p.suffix != ".npz":
            raise AtlasError(f"atlas file {str(p)!r} must end in .npz")
        with open_for_writing(p, error=AtlasError) as f:
            self._write(f)
        return p

    def _write(self, f: Any) -> None:
        np.savez(
            f,
            allow_pickle=True,  # named (its default): else mypy matches the unpacked nodes to it
            x_m=self.x_m,
            y_m=self.y_m,
            phi_rad=self.phi_rad,
            root=np.array(self.root),
            parents=self.parents,
            input_names=np.array(self.input_names, dtype=str),
            input_units=np.array(self.input_units, dtype=str),
            output_names=np.array(self.output_names, dtype=str),
            output_units=np.array(self.output_units, dtype=str),
            parameters_json=np.array(json.dumps(self.parameters, default=float)),
            **{f"node_{k}": v for k, v in self.nodes.items()},
        )


def load_atlas(path: str | Path) -> ModalAtlas:
    """Read an atlas written by :meth:`ModalAtlas.save`."""
    p = Path(path)
    if p.suffix != ".npz":
        raise AtlasError(f"{str(p)!r}: expected an .npz atlas file")
    try:
        raw = np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        raise AtlasError(
            f"{str(p)!r} is not a readable atlas file ({e}); give a file written by 'fpm-sim atlas build'"
        ) from e
    if not isinstance(raw, np.lib.npyio.NpzFile):
        raise AtlasError(f"{str(p)!r} is not an atlas file (a single array, not an .npz archive)")
    files = raw.files
    missing = [k for k in ("x_m", "node_lam", *(f"node_{k}" for k in _NODE_KEYS)) if k not in files]
    if missing:
        raise AtlasError(f"{str(p)!r} is not an atlas file (missing {', '.join(missing)})")
    return ModalAtlas(
        x_m=raw["x_m"],
        y_m=raw["y_m"],
        phi_rad=raw["phi_rad"],
        nodes={k: raw[f"node_{k}"] for k in _NODE_KEYS},
        input_names=[str(s) for s in raw["input_names"]],
        input_units=[str(s) for s in raw["input_units"]],
        output_names=[str(s) for s in raw["output_names"]],
        output_units=[str(s) for s in raw["output_units"]],
        root=_grid_index(raw["root"]),
        parents=raw["parents"],
        parameters=json.loads(str(raw["parameters_json"])),
    )


def _grid_index(values: Iterable[Any]) -> tuple[int, int, int]:
    """A node's ``(i_x, i_y, i_phi)`` from three integers (a file's array or a generator)."""
    i, j, k = values
    return (int(i), int(j), int(k))


def _bfs_tree(shape: tuple[int, int, int], root: tuple[int, int, int]) -> tuple[list[int], list[int]]:
    """Breadth-first order over the grid's flat indices and each node's parent (flat; -1 for the root)."""
    n = int(np.prod(shape))
    parent = [-2] * n
    r = int(np.ravel_multi_index(root, shape))
    parent[r] = -1
    order = [r]
    queue = deque([root])
    while queue:
        node = queue.popleft()
        f = int(np.ravel_multi_index(node, shape))
        for axis in range(3):
            for step in (-1, 1):
                nb = list(node)
                nb[axis] += step
                if 0 <= nb[axis] < shape[axis]:
                    g = int(np.ravel_multi_index(tuple(nb), shape))
                    if parent[g] == -2:
                        parent[g] = f
                        order.append(g)
                        queue.append((nb[0], nb[1], nb[2]))
    return order, parent


def _axis(values: Sequence[float], name: str) -> np.ndarray:
    a = np.asarray(sorted(float(v) for v in values))
    if a.size == 0 or np.any(~np.isfinite(a)) or np.any(np.diff(a) <= 0):
        raise AtlasError("must list distinct finite grid values", parameter=name, value=list(values))
    return a


Machine = Manipulator | Description | ImportedDescription
"""What an atlas is built on: the 3RRR, a described architecture, or an imported model that names an
``[end_effector]`` (its grid in that site's task coordinates, at the site's reference height unless given; each node's
joint values solved from its parent's, :class:`~fpm_sim.model.imported_pose.ImportedKinematics`; its reduced models'
wrench inputs and displacement outputs at that site)."""


def build_atlas(
    manip: Machine,
    *,
    x_m: Sequence[float],
    y_m: Sequence[float],
    phi_rad: Sequence[float] = (0.0,),
    z_m: float | None = None,
    options: ModelOptions | None = None,
    n_modes: int = 6,
    n_extra: int = 4,
    root: Pose | TaskPose | None = None,
    accel_fraction: float = 0.5,
    progress: bool = False,
) -> ModalAtlas:
    """Build the atlas on the grid ``x_m`` x ``y_m`` x ``phi_rad`` (m, m, rad; module docstring).

    Parameters
    ----------
    manip
        The 3RRR (:class:`~fpm_sim.config.Manipulator`) or a described architecture
        (:class:`~fpm_sim.architecture.Description`: its grid in its task coordinates; ``phi_rad`` only where it
        sets phi), or an imported model (:data:`Machine`).
    z_m
        A spatial machine's height (m; default its first check pose's, an imported model's reference): a slice.
    options
        Model options shared by every pose (default: the shared default resolution, inextensible links).
    n_modes
        Tracked (and kept) modes.
    n_extra
        Extra candidates per pose for modes crossing in from above.
    root
        Reference pose (a grid node; default the node nearest the grid centre).
    accel_fraction
        Accelerometer position on the accelerometer links (the 3RRR's distal links; the reduced models' acceleration
        outputs).
    """
    xs, ys, ps = _axis(x_m, "x_m"), _axis(y_m, "y_m"), _axis(phi_rad, "phi_rad")
    _check_mode_counts(n_modes, n_extra)
    held = _held(manip, ps, z_m)
    shape = (len(xs), len(ys), len(ps))
    opts = options or ModelOptions(axial=False)  # the shared default resolution (model.options)
    ridx = _root_index((xs, ys, ps), root)
    order, parent = _bfs_tree(shape, ridx)
    flat_poses = [_pose(held, float(x), float(y), float(p)) for x in xs for y in ys for p in ps]
    nodes: dict[str, np.ndarray] = {}
    aligned: dict[int, np.ndarray] = {}
    names: dict[str, list[str]] = {}
    it = tqdm(order, desc="atlas poses", unit="pose", leave=False) if progress else order
    node_at = _node_builder(manip, opts)
    for f in it:
        built = node_at(f, parent[f], flat_poses[f])
        system = modal_system(built, accel_fraction=accel_fraction)
        al = _align(system, aligned[parent[f]] if parent[f] >= 0 else None, n_modes, n_extra)
        aligned[f] = al.basis
        _store(nodes, shape, f, _node_model(built, system, al))
        names = {
            "input_names": list(system.input_names),
            "input_units": list(system.input_units),
            "output_names": list(system.output_names),
            "output_units": list(system.output_units),
        }
    return ModalAtlas(
        x_m=xs,
        y_m=ys,
        phi_rad=ps,
        nodes=nodes,
        root=ridx,
        parents=np.array(parent),
        parameters={
            "config": manip.name,
            "options": asdict(opts),
            "n_modes": n_modes,
            "n_extra": n_extra,
            "accel_fraction": accel_fraction,
            "nv": int(nodes["basis"].shape[3]),
            "mujoco": mujoco.__version__,
            **({} if held is None else {"architecture": held}),
        },
        **names,
    )


def _align(system: ModalSystem, parent_basis: np.ndarray | None, n_modes: int, n_extra: int) -> Alignment:
    """The node's modes matched to its parent's aligned basis (the root, ``parent_basis`` None: its own lowest)."""
    k_all = len(system.omega_rad_s)
    if n_modes + n_extra > k_all:
        raise AtlasError(f"n_modes + n_extra = {n_modes + n_extra} exceeds the {k_all} modes of the model")
    if parent_basis is None:
        return Alignment(
            np.arange(n_modes), np.ones(n_modes), np.eye(n_modes), system.phi[:, :n_modes].copy(), np.ones(n_modes)
        )
    return align_modes(parent_basis, system.phi, n_candidates=n_modes + n_extra)


def _node_builder(manip: Machine, options: ModelOptions) -> Any:
    """``(node, parent, pose) -> BuiltModel``: :func:`model_at`; on an imported model each node's joint values solved
    from its parent's (continuation along the tracking's tree: the grid stays on one assembly branch), a node the
    model cannot reach refused by its pose."""
    if not isinstance(manip, ImportedDescription):
        return lambda f, parent, pose: model_at(manip, pose, options)
    from fpm_sim.model.imported_pose import ImportedKinematics

    kin = ImportedKinematics(manip)
    joints: dict[int, dict[str, float]] = {}

    def at(f: int, parent: int, pose: TaskPose) -> BuiltModel:
        try:
            joints[f] = kin.solve(pose, start=joints.get(parent))
        except FpmSimError as e:
            raise AtlasError(
                f"grid node {pose.label(manip.task)}: {e.message}", parameter=e.parameter, hint=e.hint
            ) from None
        return _imported_at(manip, joints[f], options)

    return at


def _imported_at(desc: ImportedDescription, q: dict[str, float], options: ModelOptions) -> BuiltModel:
    """An imported model built at the joint values ``q``, its reduced model's reference point (wrench inputs,
    displacement outputs) its ``[end_effector]`` site."""
    from fpm_sim.model.imported import build_imported

    built = build_imported(desc, q, options)
    return replace(built, end_effector_site=desc.end_effector.site) if desc.end_effector else built


def model_at(manip: Machine, pose: Pose | TaskPose, options: ModelOptions) -> BuiltModel:
    """The model of the 3RRR (:func:`~fpm_sim.model.manipulator.build_manipulator`), of a described architecture
    (:func:`~fpm_sim.model.general.build_general`) or of an imported model (its joint values solved from its
    reference, :func:`fpm_sim.model.imported.build_imported`) at ``pose``."""
    if isinstance(manip, ImportedDescription):
        if not isinstance(pose, TaskPose):
            raise AtlasError(f"{manip.name} takes a fs.TaskPose")
        from fpm_sim.model.imported_pose import ImportedKinematics

        _imported_task(manip)
        return _imported_at(manip, ImportedKinematics(manip).solve(pose), options)
    if isinstance(manip, Description):
        if not isinstance(pose, TaskPose):
            raise AtlasError(f"{manip.name} takes a fs.TaskPose")
        return build_general(manip, pose, options)
    if not isinstance(pose, Pose):
        raise AtlasError("the 3RRR takes a fs.Pose (x_m, y_m, phi_rad)")
    return build_manipulator(manip, pose, options)


def _imported_task(desc: ImportedDescription) -> tuple[str, ...]:
    """An imported model's task coordinates, refused where it names no ``[end_effector]``."""
    if not desc.task or "x" not in desc.task or "y" not in desc.task:
        raise AtlasError(
            f"{desc.name} names no end effector with task coordinates x and y (its task coordinates: "
            f"{', '.join(desc.task) or 'none'}): the atlas's grid is in x and y",
            parameter="end_effector",
            hint='name its site in the description: [end_effector] site = "tool", coordinates = ["x", "y"] '
            "(docs/import.md)",
        )
    return desc.task


def _held(manip: Machine, phi: np.ndarray, z_m: float | None) -> dict[str, Any] | None:
    """What a described architecture's or an imported model's grid holds (its task coordinates and height ``z_m``,
    m); ``None`` for the 3RRR. A grid coordinate the machine lacks is refused by name."""
    if not isinstance(manip, (Description, ImportedDescription)):
        if z_m is not None:
            raise AtlasError("the 3RRR's task coordinates are x, y and phi", parameter="z_m", value=z_m, hint="drop it")
        return None
    if "phi" not in manip.task and (len(phi) != 1 or phi[0] != 0.0):
        raise AtlasError(
            f"{manip.name} has no task coordinate phi (its task coordinates are {', '.join(manip.task)})",
            parameter="phi_rad",
            value=phi.tolist(),
            hint="drop it",
        )
    if "z" not in manip.task and z_m is not None:
        raise AtlasError(
            f"{manip.name} has no task coordinate z (its task coordinates are {', '.join(manip.task)})",
            parameter="z_m",
            value=z_m,
            hint="drop it",
        )
    if isinstance(manip, ImportedDescription):
        from fpm_sim.model.imported_pose import ImportedKinematics

        _imported_task(manip)
        home = {"z": ImportedKinematics(manip).reference_pose().z_m} if z_m is None else {}
    else:
        home = manip.check_poses[0] if manip.check_poses else {}
    z = float(z_m) if z_m is not None else float(home.get("z", 0.0))
    if not math.isfinite(z):
        raise AtlasError("must be a finite height", parameter="z_m", value=z_m)
    return {"task": list(manip.task), "z_m": z}


def _pose(held: dict[str, Any] | None, x: float, y: float, phi: float) -> Pose | TaskPose:
    return Pose(x, y, phi) if held is None else TaskPose(x, y, float(held["z_m"]), phi)


def _check_mode_counts(n_modes: int, n_extra: int) -> None:
    """``n_modes`` in [1, 200] and ``n_extra`` in [0, 200], else :class:`AtlasError` naming the parameter."""
    try:
        check_count("n_modes", n_modes, low=1, high=200)
        check_count("n_extra", n_extra, low=0, high=200)
    except FpmSimError as e:
        raise AtlasError(e.message, parameter=e.parameter, value=e.value) from None


def _root_index(axes: tuple[np.ndarray, np.ndarray, np.ndarray], root: Pose | TaskPose | None) -> tuple[int, int, int]:
    """The grid index of the tracking's root: ``root`` (which must be a grid node), or the grid's middle."""
    if root is None:
        return _grid_index(int(np.argmin(np.abs(a - np.median(a)))) for a in axes)
    values = (root.x_m, root.y_m, root.phi_rad)
    ridx = _grid_index(int(np.argmin(np.abs(a - v))) for a, v in zip(axes, values))
    for a, v, i in zip(axes, values, ridx):
        if not math.isclose(float(a[i]), v, abs_tol=1e-9):
            raise AtlasError(f"the root pose {root.label()} is not a grid node")
    return ridx


def _node_model(built: BuiltModel, system: ModalSystem, al: Alignment) -> dict[str, np.ndarray]:
    """The reduced model of one node in its aligned basis ``al``: modal stiffness, damping, input and output
    matrices, the static correction of the kept modes, and the tracking's labels."""
    phi_a = al.basis
    om = system.omega_rad_s[al.index]
    q = al.rotation
    lam = q.T @ np.diag(om**2) @ q
    c_damp = system_damping_matrix(built.model, system.qpos)
    xi = phi_a.T @ c_damp @ phi_a
    gamma = phi_a.T @ system.b_q
    cq_phi = system.c_q @ phi_a
    ca_phi = system.c_a @ phi_a
    # static correction of the kept (tracked) modes: C_q (G - Phi_a Lambda^-1 Phi_a') B_q
    resid = system.flexibility - phi_a @ np.linalg.solve(lam, phi_a.T)
    d = np.vstack([system.c_q @ resid @ system.b_q, ca_phi @ gamma])
    return {
        "lam": lam,
        "xi": xi,
        "gamma": gamma,
        "cq_phi": cq_phi,
        "ca_phi": ca_phi,
        "d": d,
        "basis": phi_a,
        "qpos": system.qpos,
        "label_freq_hz": om / (2 * np.pi),
        "label_index": al.index.astype(float),
        "mac": al.mac,
        "mac_aligned": al.mac_aligned,
    }


def _store(nodes: dict[str, np.ndarray], shape: tuple[int, int, int], f: int, item: dict[str, np.ndarray]) -> None:
    """Put one node's arrays at flat index ``f`` of the grid arrays (made on first use)."""
    for key, v in item.items():
        if key not in nodes:
            nodes[key] = np.zeros(shape + np.shape(v))
        if nodes[key].shape[3:] != np.shape(v):
            raise AtlasError("poses gave models of different sizes; use one model option set for the whole grid")
        nodes[key][np.unravel_index(f, shape)] = v


def _node_label(node: tuple[float, float, float] | None) -> str:
    """``(x mm, y mm, phi rad)`` of a grid node."""
    if node is None:
        return "-"
    return f"({node[0] * 1e3:g} mm, {node[1] * 1e3:g} mm, {node[2]:g} rad)"
