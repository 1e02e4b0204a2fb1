"""Input checks shared by every config section: each failure is ``ValueError("field.path: message")``.

Run in Python before anything compiles, so bad input never turns into a NaN
inside jit.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np


def fail(field: str, msg: str):
  raise ValueError(f"{field}: {msg}")


def number(field: str, v, lo=None, hi=None, positive: bool = False) -> float:
  """A finite real (not bool), optionally > 0, >= lo, <= hi."""
  if isinstance(v, bool) or not isinstance(v, (int, float)):
    fail(field, f"expected a number, got {type(v).__name__} {v!r}")
  v = float(v)
  if not math.isfinite(v):
    fail(field, f"must be finite, got {v!r}")
  if positive and v <= 0:
    fail(field, f"must be > 0, got {v!r}")
  if lo is not None and v < lo:
    fail(field, f"must be >= {lo:g}, got {v!r}")
  if hi is not None and v > hi:
    fail(field, f"must be <= {hi:g}, got {v!r}")
  return v


def integer(field: str, v, lo: int, hi: int) -> int:
  if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
    fail(field, f"expected an integer, got {type(v).__name__} {v!r}")
  if not lo <= v <= hi:
    fail(field, f"must be in [{lo}, {hi}], got {v!r}")
  return int(v)


def vec3(field: str, v, nonneg: bool = False) -> np.ndarray:
  if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)) or len(v) != 3:
    fail(field, f"expected a list of 3 numbers, got {v!r}")
  return np.array([number(f"{field}[{i}]", x, lo=0.0 if nonneg else None) for i, x in enumerate(v)], np.float64)


def mapping(field: str, v) -> Mapping:
  if not isinstance(v, Mapping):
    fail(field, f"expected a mapping, got {type(v).__name__} {v!r}")
  return v


def check_keys(field: str, m: Mapping, allowed) -> None:
  for k in m:
    if k not in allowed:
      fail(f"{field}.{k}" if field else str(k), f"unknown key; allowed: {', '.join(allowed)}")
