"""Design studies: frequencies over designs (varied description fields) x poses, on the Dask engine.

``fpm_sim.designs.design_study(config, vary={"section.thickness_m": [0.01, 0.03]}, poses=...)`` returns a
:class:`DesignResult` (``.dataset``: an xarray Dataset; ``.table()``, ``.plot()``, ``.write(dir)``).
"""

from fpm_sim.batch.pose_loop import read_poses_csv
from fpm_sim.designs.study import (
    COMPUTED,
    DesignError,
    DesignResult,
    apply_design,
    design_study,
    factorial,
    link_mass_kg,
    moving_mass_kg,
    parse_spec,
    parse_vary,
    read_designs_csv,
)

__all__ = [
    "COMPUTED",
    "DesignError",
    "DesignResult",
    "apply_design",
    "design_study",
    "factorial",
    "link_mass_kg",
    "moving_mass_kg",
    "parse_spec",
    "parse_vary",
    "read_designs_csv",
    "read_poses_csv",
]
