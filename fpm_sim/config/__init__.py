"""The manipulator description: schema (dataclasses), TOML reading, validation, provenance.

The embedded default lives in ``fpm_sim/data/default_3rrr.toml`` (data only, no code).
"""

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
    validate,
)

__all__ = [
    "DEFAULT_CONFIG_NAME",
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
    "parse_config",
    "validate",
]
