"""The time strata of progressive passes, and the rounds that make an image time-balanced.

    pass_stratum(5)       # (0.0, 0.5): pass 5 renders the first half of the shutter
    is_round_end(16)      # True: passes 1..16 weight every part of the shutter alike

Passes come in pairs (2q - 1, 2q) that render the same stratum of the shutter
with different seeds, so the odd and the even passes are two independent,
identically distributed half images (the noise estimate compares them;
``stpm_core.progressive.noise_estimate``).  Pair q belongs to a round of B
pairs that cuts the shutter into B strata of equal mass, taken in bit-reversed
order (0, 1/2, 1/4, 3/4, ...): B = 1, 1, 2, 4, ..., STRATA_CAP, STRATA_CAP, ...
(pairs 1 | 2 | 3-4 | 5-8 | 9-16 | ... | 65-128 | 129-192 | ...).

A pass's photons and camera samples all have times in its stratum, so its photons
are 1 / B times denser in time and the time its kernel blurs over shrinks with
the pass index.  But an image is only time-balanced -- every part of the
shutter weighted alike -- when it holds whole rounds: a round cut short weights
the strata it reached twice as much as the others (bands along motion trails).
So an image holds the passes up to the last round end (:func:`is_round_end`):
1, 2, 3, 4, 8, 16, ..., 256 passes, then every 128 (2 * STRATA_CAP).  All of
this is a function of the pass index alone, the same on every machine, so
partial renders of whole rounds merge.

A render with a time limit may end with smaller rounds than these
(:class:`Rounds`): a round is only begun if it can end in time, and when the
scheduled one cannot, a round of fewer strata that can is taken instead.
"""
from __future__ import annotations

__all__ = ["STRATA_CAP", "pass_stratum", "is_round_end", "round_end_after", "round_ends_near", "round_ends_text",
           "Rounds"]

STRATA_CAP = 64  # the most strata a round cuts the shutter into (a round then is 2 * STRATA_CAP passes)
# (measured, moving caustic / receiver at 1024 passes, RMSE: cap 8 0.0085 / 0.0094, cap 64 0.0071 / 0.0074,
# no cap 0.0070 / 0.0074: late passes gain from strata as narrow as the pass count allows)


def _pair_round(q: int) -> tuple[int, int]:
    """(B, k): the number of strata of pair q's round and q's place in it (0-based)."""
    if q <= 2:
        return 1, 0
    B = 1 << ((q - 1).bit_length() - 1)        # q in (B, 2B]
    if B < STRATA_CAP or q <= 2 * STRATA_CAP:
        return B, q - B - 1
    return STRATA_CAP, (q - 2 * STRATA_CAP - 1) % STRATA_CAP


def _stratum(B: int, k: int) -> tuple[float, float]:
    """Stratum k (0-based, bit-reversed) of B (a power of two) strata."""
    bits = B.bit_length() - 1
    j = int(format(k, f"0{bits}b")[::-1], 2) if bits else 0
    return j / B, (j + 1) / B


def pass_stratum(i: int) -> tuple[float, float]:
    """The part of the shutter pass i (1-based) renders, as (lo, hi) of the shutter's mass."""
    if i < 1:
        raise ValueError(f"pass index must be >= 1, got {i}")
    return _stratum(*_pair_round((i + 1) // 2))


def is_round_end(n: int) -> bool:
    """True when passes 1..n (n >= 0) hold whole rounds: an image of them is time-balanced.

    The same holds for any range of passes between two round ends."""
    if n < 0:
        raise ValueError(f"a pass count is >= 0, got {n}")
    if n <= 4:
        return True                     # pairs 1 and 2 render the whole shutter
    if n % 2:
        return False
    q = n // 2
    if q <= 2 * STRATA_CAP:
        return q & (q - 1) == 0         # pairs 2, 4, 8, 16
    return (q - 2 * STRATA_CAP) % STRATA_CAP == 0


def round_end_after(i: int) -> int:
    """The round end at or after pass i: the last pass of the round pass i belongs to."""
    n = max(int(i), 0)
    while not is_round_end(n):
        n += 1
    return n


def round_ends_near(n: int, count: int = 3) -> list[int]:
    """Up to ``count`` round ends at or below n and as many above (for messages)."""
    below, m = [], max(n, 0)
    while m >= 0 and len(below) < count:
        if is_round_end(m):
            below.insert(0, m)
        m -= 1
    above, m = [], max(n, 0) + 1
    while len(above) < count:
        if is_round_end(m):
            above.append(m)
        m += 1
    return below + above


def round_ends_text() -> str:
    """The round ends, in words (for messages and docs)."""
    return f"0, 1, 2, 3, 4, 8, 16, ... (powers of two) up to {4 * STRATA_CAP}, then every {2 * STRATA_CAP}"


class Rounds:
    """The strata and round ends of one render's passes: the schedule above, or smaller rounds.

    ``begin(i, fit)`` is called when pass i begins a round (pass i - 1 ended one); ``fit`` is
    how many passes the round should hold at most (the time left allows, or the noise
    threshold is expected after; None: no limit).  It keeps the schedule while the
    scheduled round fits; else it begins a round of B strata (B a power of two, at most the
    schedule's at pass i) that does -- 2B passes in pairs, or one pass of the whole shutter --
    and takes such rounds from then on.  Returns the passes of the round, 0 when none fits.
    """

    def __init__(self):
        self._own = None            # (first pass, strata B, passes n) of the current round, once off the schedule

    @property
    def scheduled(self) -> bool:
        """True while the passes follow the schedule (pass_stratum, is_round_end)."""
        return self._own is None

    def stratum(self, i: int) -> tuple[float, float]:
        if self._own is None:
            return pass_stratum(i)
        start, B, _n = self._own
        return _stratum(B, (i - start) // 2) if B > 1 else (0.0, 1.0)

    def is_end(self, i: int) -> bool:
        if self._own is None:
            return is_round_end(i)
        start, _B, n = self._own
        return i == start + n - 1

    def end_of(self, i: int) -> int:
        """The last pass of the round pass i is in."""
        if self._own is None:
            return round_end_after(i)
        start, _B, n = self._own
        return start + n - 1

    def begin(self, i: int, fit: int | None) -> int:
        if self._own is None:
            n = round_end_after(i) - i + 1
            if fit is None or n <= fit:
                return n
        B = _pair_round((i + 1) // 2)[0]           # the scheduled round's strata at pass i
        if fit is None:
            fit = 2 * B
        while B > 1 and 2 * B > fit:
            B //= 2
        n = 2 * B if B > 1 else 1
        if n > fit:
            return 0
        self._own = (i, B, n)
        return n
