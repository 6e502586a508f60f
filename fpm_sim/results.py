"""What every result shares: the result contract (:class:`Result`) and conversion to JSON-ready values."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Result", "frequencies_dataset", "to_jsonable"]


@runtime_checkable
class Result(Protocol):
    """The contract every public result keeps (``isinstance(r, Result)`` checks the methods are there).

    ``to_dict()`` is JSON-ready (:func:`to_jsonable`: no numpy values, no Python reprs), ``table()`` is a
    plain-text table and ``plot(ax=None)`` draws on a new figure, or into the given axes (the result's main
    panel when it has several), and returns the ``Figure``. Checked for every result type by
    ``tests/test_results.py``.
    """

    def to_dict(self) -> dict[str, Any]:
        """Return JSON-ready values (SI units, named with their unit)."""

    def table(self) -> str:
        """Return a plain-text table."""

    def plot(self, ax: Any = None) -> Figure:
        """Draw on a new figure or into ``ax``; return the ``Figure``."""


def frequencies_dataset(
    freq_hz: Any,
    *,
    x_mm: Any,
    y_mm: Any,
    phi_rad: Any,
    status: Any,
    leading: dict[str, Any] | None = None,
    data_vars: dict[str, Any] | None = None,
    coords: dict[str, Any] | None = None,
    attrs: dict[str, Any] | None = None,
) -> Any:
    """Build the one shape of frequencies over poses: an :class:`xarray.Dataset` (xarray imported lazily).

    Variable ``freq_hz`` (Hz, NaN where not computed) with dimensions ``(*leading, "pose", "mode")``; ``mode``
    numbered from 1; coordinates ``x_mm``, ``y_mm``, ``phi_rad`` on ``pose`` and ``status`` (``ok``,
    ``near_singular``, ``singular``, ``unreachable``, ...) on ``pose`` or on ``(*leading, "pose")``.

    Parameters
    ----------
    freq_hz
        ``(*leading, n_poses, n_modes)`` frequencies (Hz).
    x_mm, y_mm, phi_rad
        ``(n_poses,)`` pose coordinates (mm, mm, rad).
    status
        ``(n_poses,)`` or ``(*leading, n_poses)`` status strings.
    leading
        Leading dimensions in order, name -> coordinate values (e.g. ``{"design": [0, 1, 2]}``, ``{"draw": ...}``).
    data_vars, coords, attrs
        More variables, coordinates and attributes, as :class:`xarray.Dataset` takes them.
    """
    import xarray as xr

    lead = dict(leading or {})
    f = np.asarray(freq_hz, float)
    if f.ndim != len(lead) + 2:
        raise ValueError(f"freq_hz has {f.ndim} dimensions; expected {len(lead) + 2} ({', '.join(lead)}, pose, mode)")
    st = np.asarray(status, dtype=str)
    st_dims = ("pose",) if st.ndim == 1 else (*lead, "pose")
    all_coords: dict[str, Any] = {
        **{k: np.asarray(v) for k, v in lead.items()},
        "pose": np.arange(f.shape[-2]),
        "mode": np.arange(1, f.shape[-1] + 1),
        "x_mm": ("pose", np.asarray(x_mm, float)),
        "y_mm": ("pose", np.asarray(y_mm, float)),
        "phi_rad": ("pose", np.asarray(phi_rad, float)),
        "status": (st_dims, st),
        **(coords or {}),
    }
    variables = {"freq_hz": ((*lead, "pose", "mode"), f), **(data_vars or {})}
    return xr.Dataset(variables, coords=all_coords, attrs=dict(attrs or {}))


def to_jsonable(obj: Any) -> Any:
    """Convert numpy values, tuples and infinities into values ``json.dumps`` accepts.

    Non-finite floats become their string (``"inf"``, ``"nan"``) so that the JSON stays standard.
    """
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else str(f)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
