"""A synthetic posterior.nc in the calibration's format (``fpm_sim.study.posterior``): six perturbed copies of the
default description (section height 14.5-16 mm, platform 4.0-4.8 kg), written with ArviZ. Used by the bands
tests of the library, the command line, the design studies and the result contract."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fpm_sim.config import default_config
from fpm_sim.config.schema import config_to_toml
from fpm_sim.study.identify.parameters import parameter_set

SEGMENTS = 4
"""The likelihood's resolution the file states (``fpm_sim_segments``)."""
GROUPS = ("section-height", "hardware")
HEIGHTS_M = np.array([0.0150, 0.0155, 0.0160, 0.0145, 0.0158, 0.0152])
PLATFORM_KG = np.array([4.2, 4.6, 4.4, 4.0, 4.8, 4.5])


def write_posterior(
    path: str | Path,
    *,
    draws: dict[str, Any] | None = None,
    attrs: dict[str, Any] | None = None,
    branch: Any = None,
    drop: tuple[str, ...] = (),
    segments: int = SEGMENTS,
) -> Path:
    """A posterior.nc in the calibration's format: one chain, one variable per free parameter (named as the
    parameter set names them), the four attributes; ``draws`` overrides values by name, ``attrs`` sets (or with
    ``None`` removes) attributes, ``branch`` adds ``(6, 3)`` elbow branches, ``drop`` leaves parameters out."""
    import arviz as az

    base = default_config()
    ps = parameter_set(base, list(GROUPS))
    n = len(HEIGHTS_M)
    values = {name: np.full(n, x) for name, x in zip(ps.names, ps.x0)}
    values["section.height_m"] = HEIGHTS_M.copy()
    values["hardware.platform.mass_kg"] = PLATFORM_KG.copy()
    values.update(draws or {})
    for name in drop:
        values.pop(name)
    post = {k: np.asarray(v, float)[None, :] for k, v in values.items()}
    post["likelihood.discrepancy_rel"] = np.linspace(0.02, 0.04, n)[None, :]
    dims = {}
    if branch is not None:
        post["geometry.elbow_branch"] = np.asarray(branch, np.int8)[None, :, :]
        dims["geometry.elbow_branch"] = ["arm"]
    idata = az.from_dict(posterior=post, dims=dims)
    idata.posterior.attrs.update(
        {
            "fpm_sim_base_config": config_to_toml(base),
            "fpm_sim_free_groups": ",".join(GROUPS),
            "fpm_sim_segments": segments,
            "fpm_sim_command": "test fixture",
        }
    )
    for key in attrs or {}:
        if attrs[key] is None:
            del idata.posterior.attrs[key]
        else:
            idata.posterior.attrs[key] = attrs[key]
    idata.to_netcdf(str(path))
    return Path(path)


FIVE_BAR = Path(__file__).resolve().parents[2] / "examples" / "architectures" / "five_bar.toml"
MASS_PATH = "lumps.end_effector.mass_kg"
"""The free path of the described posterior."""
MASSES_KG = np.array([0.15, 0.25, 0.35, 0.45, 0.30])
"""The draws of the five-bar's end-effector mass (its file: 0.25 kg)."""


def write_described_posterior(path: str | Path, *, segments: int = 2, masses: Any = MASSES_KG) -> Path:
    """A described machine's posterior.nc, as ``fpm-sim calibrate --config five_bar.toml`` writes it: the five-bar's
    file as the base (its TOML), one free dotted path (:data:`MASS_PATH`, the draws :data:`MASSES_KG`) and an
    independent relative discrepancy."""
    import arviz as az

    from fpm_sim.architecture import description_toml, load_description

    n = len(masses)
    post = {MASS_PATH: np.asarray(masses, float)[None, :], "likelihood.discrepancy_rel": np.full((1, n), 0.02)}
    idata = az.from_dict(posterior=post)
    idata.posterior.attrs.update(
        {
            "fpm_sim_base_config": description_toml(load_description(FIVE_BAR)),
            "fpm_sim_free_groups": MASS_PATH,
            "fpm_sim_segments": segments,
            "fpm_sim_command": "test fixture (described)",
        }
    )
    idata.to_netcdf(str(path))
    return Path(path)
