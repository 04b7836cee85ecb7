"""Which sizes `armfleet capacity` runs in real time: from a prediction, bisecting.

Why apart: the rules are small and pure (a size and a run's result in, the next size out), so
a test holds them to their promises (every miss steps down, the search ends) without a
server.
"""

from __future__ import annotations

from typing import Any

UNDER = 0.97  # a prediction is taken a little under (a rate measured is never quite kept)
MAX_RUNS = 3  # realtime runs per engine once one held (the check not counted); 2 more before
RESOLUTION = 0.04  # an answer within this share of the next size to try is close enough
# A held run whose sim thread was busy for less than this share of the wall has room for more.
ROOM = 0.9


def _floor8(x: float) -> int:
    """Worlds to try: whole multiples of 8 from 16 up (rounded down), else at least 1."""
    return max(1, int(x)) if x < 16 else int(x // 8) * 8


def _below(n: int, rtf: float) -> int:
    """The next N after a miss at `n` with `rtf`: what that rate holds, a little under, and
    always fewer than `n`."""
    return max(1, min(_floor8(n * min(rtf, 1.0) * UNDER), n - (8 if n >= 24 else 1)))


def next_size(n: int, res: dict[str, Any], lo: int | None, hi: int | None) -> int | None:
    """The size to run after a realtime run `res` at `n`, or None when the answer is found.

    `lo`/`hi`: the most worlds held and the fewest missed so far (this run included), the
    bracket the answer lies in. A miss predicts from its RTF (the loop ran flat out: the rate
    it kept is what it holds); a hold predicts from how busy the sim thread was (`tick_share`:
    the share of the wall it spent in ticks), when that leaves room. The prediction is kept
    inside the bracket (its middle when it falls outside), and a step smaller than
    `RESOLUTION` of the size ends the search: each realtime run costs seconds, and a 10 s
    window tells sizes that close apart no better than the box's drift does.
    """
    if res["held"]:
        busy = res.get("tick_share")
        if not busy or busy >= ROOM:
            return None
        guess = _floor8(n / busy * UNDER)
    else:
        guess = _below(n, res["realtime_factor"])
    if (lo is not None and guess <= lo) or (hi is not None and guess >= hi):
        if lo is None:  # nothing held yet: down from the miss however far that is
            return guess if guess < n else None
        if hi is None:
            return None
        guess = _floor8((lo + hi) / 2)
    near = max(8, RESOLUTION * n) if n >= 24 else 1
    if abs(guess - n) < near or (lo is not None and abs(guess - lo) < near):
        return None
    return guess


def capped(nxt: int | None, n: int, predicted: int, most: int | None) -> int | None:
    """`nxt` (from `next_size`) no higher than fast mode predicted (the loop flat out: real
    time cannot hold more) nor than `most`; None when that leaves no step up worth a run."""
    if nxt is None or nxt <= n:
        return nxt
    nxt = min(nxt, predicted, most or nxt)
    return nxt if nxt - n >= max(8, RESOLUTION * n) else None
