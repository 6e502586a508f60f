"""Helpers shared by several test modules (``from tests.helpers.posterior import write_posterior``)."""
