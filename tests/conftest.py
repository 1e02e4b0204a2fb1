"""Shared test set-up: JAX persistent compilation cache and headless plotting."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
_CACHE = os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", os.path.join(os.path.dirname(os.path.dirname(__file__)), ".jax_cache")
)

import jax  # noqa: E402

jax.config.update("jax_compilation_cache_dir", _CACHE)
# cache every compiled MJX function: compiles here take seconds to a minute
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
