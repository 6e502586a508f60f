"""The one error hierarchy of fpm-sim.

Every failure a user can cause (a bad description, an unreachable pose, an unwritable output, a
diverging simulation) raises a subclass of :class:`FpmSimError`; the command line maps exactly these to
exit code 2 with one ``error: ...`` line. Any other exception is a bug in fpm-sim and keeps its traceback.
Warnings that concern the user's input derive from :class:`FpmSimWarning`.
"""

from __future__ import annotations

__all__ = ["FpmSimError", "FpmSimWarning"]


class FpmSimError(ValueError):
    """A failure caused by the input; the message names the parameter or file and how to fix it.

    Derives from :class:`ValueError` so that callers catching ``ValueError`` keep working.
    """


class FpmSimWarning(UserWarning):
    """A result computed from questionable input (near a singularity, coarse resolution, ...)."""
