"""Inter-labeler agreement: Krippendorff's α for nominal data (pure numpy).

Reliability data are units (queries) each with the values (labels) the coders (labelers) gave it;
only units with m_u ≥ 2 values are pairable. Following Krippendorff (2011), "Computing
Krippendorff's Alpha-Reliability", the coincidence matrix is

    o_ck = Σ_u (number of ordered pairs (c, k) of values in unit u, from different coders) / (m_u − 1),

n_c = Σ_k o_ck, n = Σ_c n_c, and for nominal data

    α = 1 − D_o / D_e = 1 − (n − 1) · Σ_{c≠k} o_ck / Σ_{c≠k} n_c n_k.

α is 1 for perfect agreement, 0 for agreement at chance, negative below it; undefined (None) when
nothing is pairable or every pairable value is the same (D_e = 0).

Per coder, `coder_alpha` restricts the observed disagreement to the pairs the coder is part of
(each weighted 1/(m_u − 1) as above) and keeps the expected disagreement of all the data:
α_i = 1 − D_o(i) / D_e. It says how far a labeler agrees with the others, on the same scale as α.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from typing import Any

import numpy as np

Unit = Mapping[Any, int]  # coder (any hashable) → value, for one unit


def _values(units: Sequence[Unit]) -> list[int]:
    return sorted({v for u in units if len(u) >= 2 for v in u.values()})


def coincidences(units: Sequence[Unit], values: list[int], coder: Hashable | None = None) -> np.ndarray:
    """o_ck over the pairable units; with `coder`, only the ordered pairs that include that coder."""
    index = {v: i for i, v in enumerate(values)}
    o = np.zeros((len(values), len(values)))
    for unit in units:
        m = len(unit)
        if m < 2 or (coder is not None and coder not in unit):
            continue
        items = list(unit.items())
        for a, va in items:
            for b, vb in items:
                if a == b or (coder is not None and coder not in (a, b)):
                    continue
                o[index[va], index[vb]] += 1.0 / (m - 1)
    return o


def _expected(o: np.ndarray) -> float:
    """D_e · n (n − 1)'s numerator: Σ_{c≠k} n_c n_k."""
    n_c = o.sum(axis=1)
    return float(n_c.sum() ** 2 - (n_c**2).sum())


def alpha(units: Sequence[Unit]) -> float | None:
    """Krippendorff's α (nominal) of the units; None where it is undefined."""
    values = _values(units)
    o = coincidences(units, values)
    n = o.sum()
    expected = _expected(o)
    if n < 2 or expected <= 0:
        return None
    observed = n - np.trace(o)
    return float(1.0 - (n - 1) * observed / expected)


def coder_alpha(units: Sequence[Unit], coder: Hashable) -> float | None:
    """α_i: the observed disagreement of `coder`'s pairs over the expected disagreement of all units."""
    values = _values(units)
    everything = coincidences(units, values)
    n = everything.sum()
    expected = _expected(everything)
    mine = coincidences(units, values, coder)
    if n < 2 or expected <= 0 or mine.sum() == 0:
        return None
    d_observed = (mine.sum() - np.trace(mine)) / mine.sum()
    d_expected = expected / (n * (n - 1))
    return float(1.0 - d_observed / d_expected)
