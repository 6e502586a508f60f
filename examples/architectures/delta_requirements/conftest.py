"""Load fpm-sim's pytest plugin on purpose (it is not auto-registered): the Delta's requirements file is collected
as one test per requirement."""

pytest_plugins = ["fpm_sim.pytest_plugin"]
