"""Shared test set-up: headless plotting; the package itself sets the XLA:CPU flag and the
persistent compilation cache (mjx_damage/runtime.py), as it does for every user."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import mjx_damage  # noqa: E402,F401  (before any test starts a JAX backend)
