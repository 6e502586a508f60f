"""The manipulator description: schema (dataclasses), TOML reading, validation, provenance, and the
dotted-name editor (``parameter_value``, ``with_parameter``).

The embedded default lives in ``fpm_sim/data/default_3rrr.toml`` (data only, no code).
"""

from fpm_sim.config.edit import EXAMPLE_PARAMETERS, parameter_value, with_parameter
from fpm_sim.config.schema import (
    DEFAULT_CONFIG_NAME,
    Compliance,
    ConfigError,
    Damping,
    Geometry,
    Hardware,
    LumpedMass,
    Manipulator,
    Material,
    Motors,
    RigConfig,
    Section,
    config_to_toml,
    default_config,
    default_config_text,
    load_config,
    parse_config,
    rectangle_torsion_constant_m4,
    validate,
)

__all__ = [
    "DEFAULT_CONFIG_NAME",
    "EXAMPLE_PARAMETERS",
    "Compliance",
    "ConfigError",
    "Damping",
    "Geometry",
    "Hardware",
    "LumpedMass",
    "Manipulator",
    "Material",
    "Motors",
    "RigConfig",
    "Section",
    "config_to_toml",
    "default_config",
    "default_config_text",
    "load_config",
    "parameter_value",
    "parse_config",
    "rectangle_torsion_constant_m4",
    "validate",
    "with_parameter",
]
