"""The one progress protocol of raysim, a leaf module: ``progress(stage, fraction)``.

Every long call that reports progress (a trace, a PO sum, a simulation, an inversion, a scan,
a dataset run) takes an optional ``progress`` argument with the signature

    progress(stage: str, fraction: float) -> None

``stage`` is a short human-readable label of the current step ("ideal: rays",
"iteration 2/3", "sample 12 of 40"); ``fraction`` is the share of the whole call done, from
0 to 1 (reaching 1.0 at the end). Callers may pass any callable of that shape (a lambda, a
bound method of a progress bar); ``None`` means silence. A caller never learns anything else
through it, so a progress callback cannot change a result.

The helpers below compose callbacks: :func:`within` maps a sub-step's 0..1 onto a slice of
the parent's range, :func:`monotone` keeps fractions from going back when several parts of a
call report, :func:`silent` is the do-nothing default.
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    """``progress(stage, fraction)``: a label of the current step and the share done (0..1)."""

    def __call__(self, stage: str, fraction: float, /) -> None: ...


def silent(stage: str, fraction: float, /) -> None:
    """The progress callback that reports nothing."""


def within(progress: Progress | None, start: float, stop: float, label: str = "") -> Progress:
    """A callback for a sub-step that covers ``start``..``stop`` of ``progress``'s range.

    The sub-step's fraction f in 0..1 is reported as ``start + (stop - start) f`` (f clipped
    to 0..1), its stage prefixed by ``label: `` when a label is given.
    """
    if progress is None:
        return silent
    span = stop - start

    def report(stage: str, fraction: float, /) -> None:
        text = f"{label}: {stage}" if label else stage
        progress(text, start + span * min(max(float(fraction), 0.0), 1.0))

    return report


def monotone(progress: Progress) -> Progress:
    """``progress`` with fractions that never decrease (parts of a call report separately)."""
    done = [0.0]

    def report(stage: str, fraction: float, /) -> None:
        done[0] = max(done[0], float(fraction))
        progress(stage, done[0])

    return report


__all__ = ["Progress", "monotone", "silent", "within"]
