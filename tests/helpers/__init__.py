"""Helpers shared by the tests and the studies (``studies/``): truths and settings, no tests of their own."""
