"""Argument checks shared by the simulator options, the environments and their resets.

Every public argument goes through one of these, so that a wrong value raises a ``ValueError``
(or, for an unknown argument name, a ``ValueError`` listing the valid names) that names the
argument, instead of being coerced silently (``strict=0.5``, ``dt=True``, ``stance_side=1.9``)
or failing later inside compiled code.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping
from numbers import Integral, Real
from typing import Any

import numpy as np


def check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool; only ``True``/``False`` (or numpy's) are accepted."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ValueError(f"{name} must be True or False, got {value!r}")


def check_real(
    name: str,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    *,
    low_open: bool = False,
    unit: str = "",
) -> float:
    """``value`` as a finite float in [low, high] (``(low, high]`` with ``low_open``).

    Booleans, strings and other non-numbers are refused (``dt=True`` is not 1 s).
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        raise ValueError(f"{name} must be a real number{unit}, got {value!r}")
    v = float(value)
    below = v <= low if low_open else v < low
    if not math.isfinite(v) or below or v > high:
        lo = "(" if low_open else "["
        raise ValueError(
            f"{name} must be finite and in {lo}{low:g}, {high:g}]{unit}, got {value!r}"
        )
    return v


def check_int(name: str, value: Any, low: int, high: int) -> int:
    """``value`` as an int in [low, high]; booleans and non-integral floats are refused."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Integral):
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    v = int(value)
    if not low <= v <= high:
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return v


def check_choice(name: str, value: Any, choices: Iterable[Any]) -> Any:
    """``value`` if it is one of ``choices`` (compared only with values of the same type)."""
    choices = tuple(choices)
    for c in choices:
        if type(value) is type(c) and value == c:
            return value
    raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


def check_array(
    name: str, value: Any, shape: tuple[int, ...], max_abs: float = math.inf, unit: str = ""
) -> np.ndarray:
    """``value`` as a float64 array of ``shape`` with finite entries of magnitude <= max_abs.

    Strings, booleans and objects are refused (``posture=["0", ...]`` is not numbers).
    """
    try:
        a = np.asarray(value)
    except (ValueError, TypeError) as e:  # ragged nesting
        raise ValueError(f"{name} must be an array of shape {shape}, got {value!r}") from e
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name} must hold real numbers, got dtype {a.dtype} ({value!r})")
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    a = a.astype(np.float64)
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) > max_abs):
        raise ValueError(f"{name} must be finite with |entries| <= {max_abs:g}{unit}, got {a}")
    return a


def check_mapping(name: str, value: Any, valid: Iterable[str]) -> Mapping[str, Any]:
    """``value`` if it is a mapping whose keys are all among ``valid`` (else a ValueError)."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a dict, got {value!r}")
    check_names(name, value.keys(), valid)
    return value


def check_names(what: str, given: Iterable[Any], valid: Iterable[str]) -> None:
    """ValueError naming every unknown name in ``given`` and the valid names.

    The closest valid name is suggested ("did you mean 'strict'?").
    """
    valid = sorted(valid)
    unknown = [k for k in given if k not in valid]
    if not unknown:
        return
    hints = []
    for k in unknown:
        close = difflib.get_close_matches(str(k), valid, n=1) if isinstance(k, str) else []
        hints.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise ValueError(f"unknown {what}: {', '.join(hints)}; valid: {', '.join(valid)}")


def check_seeds(seed: Any, n: int) -> list[int]:
    """``seed`` (an int, or a list of ``n`` ints) as ``n`` seeds; anything else is refused."""

    def ok(s: Any) -> bool:
        return isinstance(s, int | np.integer) and not isinstance(s, bool | np.bool_) and s >= 0

    if ok(seed):
        return [int(seed) + i for i in range(n)]
    if not isinstance(seed, list | tuple | np.ndarray) or not all(ok(s) for s in seed):
        raise ValueError(f"seed must be None, an int >= 0 or a list of {n} ints >= 0, got {seed!r}")
    if len(seed) != n:
        raise ValueError(f"seed: expected {n} seeds, got {len(seed)}")
    return [int(s) for s in seed]
