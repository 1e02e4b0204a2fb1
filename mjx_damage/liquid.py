"""Liquid particles (MuJoCo has none): pure JAX state advanced each substep.

Seam used by :mod:`mjx_damage.physics`: ``build`` (None when no liquid is
configured), ``init`` and ``advance``. Without liquid nothing is computed and
every link's exposure stays 0.
"""

from __future__ import annotations


def build(model, binding, raw):
  if raw.get("liquid") is not None:
    raise ValueError("liquid: particles are not available in this version")
  return None


def init(binding, rng):
  return None


def advance(m, binding, d, ds, dt):
  return ds
