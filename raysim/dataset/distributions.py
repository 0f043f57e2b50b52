"""Random parameters of a dataset spec: a fixed number or one of a few named distributions.

In the spec TOML a parameter is either a bare number (always that value) or an inline table
naming its law and two numbers, in the unit of the key's name (``rms_um``, ``sigma_m``):

- ``{ uniform = [lo, hi] }``: uniform on [lo, hi];
- ``{ loguniform = [lo, hi] }``: log-uniform on [lo, hi], 0 < lo;
- ``{ normal = [mean, sd] }``: Gaussian (only where a value may take any sign);
- ``{ integers = [lo, hi] }``: an integer drawn uniformly from lo..hi, both included.

Each law knows its support, so a key that needs a positive value refuses a law that could
give a negative one at load time, not after hours of simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

LAWS = ("uniform", "loguniform", "normal", "integers")


@dataclass(frozen=True)
class Distribution:
    """A scalar law: ``law`` in :data:`LAWS` or ``fixed``; ``a``, ``b`` its two numbers."""

    law: str
    a: float
    b: float = math.nan

    @property
    def support(self) -> tuple[float, float]:
        """Smallest and largest value a draw can take."""
        if self.law == "fixed":
            return self.a, self.a
        if self.law == "normal":
            return (-math.inf, math.inf) if self.b > 0 else (self.a, self.a)
        return self.a, self.b

    @property
    def mean(self) -> float:
        """Expected value of a draw (the number the tests compare sample means with)."""
        if self.law in ("fixed", "normal"):
            return self.a
        if self.law == "loguniform":
            return (self.b - self.a) / math.log(self.b / self.a) if self.b > self.a else self.a
        return 0.5 * (self.a + self.b)

    def draw(self, rng: np.random.Generator, size: int | None = None) -> Any:
        """One value (or ``size`` values) from ``rng``."""
        if self.law == "fixed":
            return self.a if size is None else np.full(size, self.a)
        if self.law == "uniform":
            return rng.uniform(self.a, self.b, size)
        if self.law == "loguniform":
            return np.exp(rng.uniform(math.log(self.a), math.log(self.b), size))
        if self.law == "normal":
            return rng.normal(self.a, self.b, size)
        value = rng.integers(int(self.a), int(self.b), size, endpoint=True)
        return int(value) if size is None else value

    def describe(self) -> str:
        return f"{self.a:g}" if self.law == "fixed" else f"{self.law}({self.a:g}, {self.b:g})"


def parse_distribution(value: Any, name: str, lo: float | None = None, hi: float | None = None,
                       integer: bool = False) -> Distribution:
    """A :class:`Distribution` from a spec value, checked against the bounds [lo, hi].

    Raises ``ValueError`` with a one-line message naming ``name``; the spec loader adds
    the file name.
    """
    if isinstance(value, bool):
        raise ValueError(f"'{name}' must be a number or a table like {{ uniform = [lo, hi] }}")
    if isinstance(value, int | float):
        if not math.isfinite(value):
            raise ValueError(f"'{name}' must be a finite number, got {value!r}")
        if integer and (not float(value).is_integer()):
            raise ValueError(f"'{name}' must be an integer, got {value!r}")
        dist = Distribution("fixed", float(value))
    elif isinstance(value, dict):
        if len(value) != 1 or next(iter(value)) not in LAWS:
            raise ValueError(f"'{name}' must name one law of {', '.join(LAWS)}, "
                             f"as {{ uniform = [lo, hi] }}; got {value!r}")
        law, pair = next(iter(value.items()))
        ok = (isinstance(pair, list) and len(pair) == 2
              and all(isinstance(v, int | float) and not isinstance(v, bool) for v in pair))
        if not ok or not all(math.isfinite(v) for v in pair):
            raise ValueError(f"'{name}.{law}' must be two finite numbers [a, b], got {pair!r}")
        a, b = float(pair[0]), float(pair[1])
        if law in ("uniform", "loguniform", "integers") and b < a:
            raise ValueError(f"'{name}.{law}' needs lo <= hi, got [{a:g}, {b:g}]")
        if law == "loguniform" and a <= 0:
            raise ValueError(f"'{name}.loguniform' needs lo > 0, got {a:g}")
        if law == "normal" and b < 0:
            raise ValueError(f"'{name}.normal' needs sd >= 0, got {b:g}")
        if law == "integers" and not (a.is_integer() and b.is_integer()):
            raise ValueError(f"'{name}.integers' needs integer bounds, got [{a:g}, {b:g}]")
        if integer and law != "integers":
            raise ValueError(f"'{name}' must be an integer or {{ integers = [lo, hi] }}, got {law}")
        dist = Distribution(law, a, b)
    else:
        raise ValueError(f"'{name}' must be a number or a table like {{ uniform = [lo, hi] }}, "
                         f"got {value!r}")
    s_lo, s_hi = dist.support
    if lo is not None and s_lo < lo:
        raise ValueError(f"'{name}' must stay >= {lo:g}; {dist.describe()} can give {s_lo:g}")
    if hi is not None and s_hi > hi:
        raise ValueError(f"'{name}' must stay <= {hi:g}; {dist.describe()} can give {s_hi:g}")
    return dist
