"""How floats enter an identity hash (a problem's id, a region cache key), by versioned rule.

An identity must be the same on every machine for the same problem. Floats that are posed by
computation (IK, products of rotations) carry last-bit noise that differs between CPUs and
libraries: a value that is 3e-17 on one machine is -2e-17 on another. Rounded to 9 decimals
both are zero, but one is `-0.0`, and `json.dumps` and `tobytes` write the two zeros apart.

Rules (a frozen dataset names the rule its ids were made with, in its manifest):

- `round9` (datasets up to recycle-v3): each value rounded to 9 decimals; the sign of a zero
  counts. Kept so that the shipped datasets keep their ids.
- `round9-unsigned-zero` (the current rule): each value rounded to 9 decimals, and every value
  whose magnitude is below `ZERO_BELOW` (so every zero of either sign) written as `0.0`.

A value near a rounding boundary (x.xxxxxxxxx5) can still round apart on two machines; that is
rare for values that are not exactly such halves, and no rule of fixed decimals avoids it. What
the current rule removes is the common case: a value that should be zero.

Hashes made to detect edits (`record_hash`, the dataset hash, `trial_id`) stay exact.
"""

from __future__ import annotations

import numpy as np

from scenes.errors import SuiteError

#: Decimals kept when hashing configurations (rad) and poses (m): far below any planner's
#: tolerance, far above float noise of a JSON round trip.
DECIMALS = 9
#: Below this magnitude a value hashes as 0.0 under the current rule (half the last kept decimal).
ZERO_BELOW = 0.5 * 10.0 ** -DECIMALS

LEGACY_RULE = "round9"
CURRENT_RULE = "round9-unsigned-zero"
RULES = {
    LEGACY_RULE: "rounded to 9 decimals; the sign of a zero counts (datasets up to recycle-v3)",
    CURRENT_RULE: f"rounded to 9 decimals; every |value| < {ZERO_BELOW:g}, and every zero of either sign, as 0.0",
}


def check_rule(rule: str) -> str:
    """`rule` itself, or a SuiteError naming it and the known rules."""
    if rule not in RULES:
        raise SuiteError(f"identity rule {rule!r} is unknown; allowed: {', '.join(RULES)}")
    return rule


def hashed(values, *, rule: str = CURRENT_RULE) -> np.ndarray:
    """The values as an identity hashes them under `rule` (float array of the input's shape)."""
    check_rule(rule)
    a = np.asarray(values, float)
    r = np.round(a, DECIMALS)
    if rule == CURRENT_RULE:
        r = np.where(np.abs(a) < ZERO_BELOW, 0.0, r) + 0.0  # + 0.0 turns -0.0 into 0.0
    return r


def hashed_list(values, *, rule: str = CURRENT_RULE) -> list:
    """`hashed` as nested lists of Python floats (for JSON)."""
    return hashed(values, rule=rule).tolist()


def hashed_scalar(value: float, *, rule: str = CURRENT_RULE) -> float:
    """One value as `hashed` writes it."""
    return float(hashed(float(value), rule=rule))
