"""Load fpm-sim's pytest plugin on purpose (it is not auto-registered): fixtures fpm_config and fpm_sweep,
the fpm_requirement marker, and collection of fpm-requirements*.toml as one test per requirement."""

pytest_plugins = ["fpm_sim.pytest_plugin"]
