"""Errors of the scanning rig a user can cause; the CLI prints each as one line, exit status 2.

:class:`raysim.errors.InstrumentError` covers the instruments themselves (unreachable, silent,
wrong identity, error queue, motion not reaching its target).
"""

from __future__ import annotations

from raysim.errors import InstrumentError, RaysimError

__all__ = ["InstrumentError", "JournalError", "PlanError"]


class PlanError(RaysimError, ValueError):
    """A scan plan or rig file is invalid (unknown key, bad value, position out of reach)."""


class JournalError(RaysimError):
    """A scan journal cannot be used (belongs to another plan, corrupt, exists without resume)."""
