"""Process-wide JAX settings the package applies on import, before JAX's backends start.

Two settings, each with an environment variable to change or switch it off (the XLA:CPU flags and the
persistent compilation cache), and two a command opts into (deterministic GPU kernels, matmul precision):

**XLA:CPU flags** (``MJX_DAMAGE_XLA_CPU_FIX=0`` to leave XLA_FLAGS alone): two, each
added unless ``XLA_FLAGS`` already names it. Both change only the CPU compiler.

*Scheduler.*
jaxlib 0.10.2's LAPACK kernels (``lapack_spotrf_ffi``, the batched Cholesky
that MJX's Newton solver calls every substep) split their batch into tasks on
XLA's intra-op thread pool and then *block* until those tasks finish
(``jax::ParallelBatchMap`` → ``absl::BlockingCounter::Wait``). XLA:CPU's thunk
executor runs independent thunks concurrently on the same pool. When as many
independent batched Cholesky thunks as the pool has threads (2 on a 2-core
machine) start at once, every worker waits for tasks that no free worker is
left to run: a deadlock, process idle, all threads in futex waits. The
default *concurrency-optimized* HLO scheduler (BFS order) puts independent
instructions side by side and gives them separate buffers, which is what lets
the executor run them together. ``--xla_cpu_enable_concurrency_optimized_scheduler=false``
selects XLA's memory-minimising DFS scheduler: buffers are reused along one
chain, so the executor sees dependencies between the Cholesky thunks and runs
them one after another. jaxlib 0.11 removes the blocking parallel path from
its open-source LAPACK kernels; 0.10.2 is the newest release on PyPI, so the
package sets the flag. It only changes the CPU compiler; GPU runs are
unaffected. ``benchmarks/cpu_stall.py`` loops the triggering calls under a
watchdog; ``docs/cpu_stall.md`` has the evidence.

*Fusion emitters.* ``--xla_cpu_use_fusion_emitters=false``: jaxlib 0.10.2's
new XLA:CPU fusion emitters make MJX's forward kinematics cost exponential
in the depth of a kinematic chain (``mjx.kinematics`` composes each body's
quaternion with its parent's level by level, and the emitted loop fusions
recompute the parent's components for every component they read). A chain
of 6 hinges takes 3 ms per call of 4 environments, 8 hinges 0.65 s; the
Panda's 7 joints + fingers made a place_plate control step ≈ 180× slower than
with the older elemental emitters, which take 0.35 ms for the 8-hinge chain
(``benchmarks/panda_speed.py``, ``docs/panda_speed.md``). jaxlib 0.11 no longer
knows this flag and aborts the process on an unknown XLA flag, so it is added
only for jaxlib < 0.11 (:func:`cpu_flags`).

**Deterministic GPU kernels** (opt-in: :func:`use_deterministic_gpu_ops`, the ``--deterministic`` option
of ``mjx-damage train``, ``benchmarks/rl_multiseed.py`` and ``benchmarks/rl_brax_ppo.py``). XLA's GPU
scatter-adds and reductions accumulate in whatever order the threads finish, so two runs of one seed part
from their first logged values on, and can end apart (on Pick Egg, one found the grip, the other kept still). With
``--xla_gpu_deterministic_ops=true`` XLA picks kernels with a fixed order: two runs of one command on two
H200s gave identical curves and final policies, at 0.73–0.76× (our trainer) and 0.72–0.94× (Brax's PPO)
the training throughput of runs without it (``benchmarks/training_repeatability.py``; docs/safe_rl.md,
"Repeatable GPU runs"). CPU runs are repeatable without it.

**Matrix-product precision** (opt-in: :func:`use_matmul_precision`, the ``--matmul-precision`` option of the
same three commands and ``mjx-damage eval``; JAX's own ``JAX_DEFAULT_MATMUL_PRECISION`` has the same effect). By default JAX computes
float32 matrix products at TF32 (a 10-bit mantissa) on recent NVIDIA GPUs and in full float32 on a CPU, so MJX on
a GPU is, in its last bits, another simulator; a policy can learn behaviour that only TF32 makes reliable (one
Shelve Item policy carried in 100 % of episodes at TF32 and 48 % at float32: docs/rl_task_design.md, "TF32 in
the simulation"). ``float32`` traces every program from then on at full precision; :func:`matmul_precision`
says which is in force, for results files.

**Persistent compilation cache** (``MJX_DAMAGE_CACHE_DIR=<dir>`` to move it,
``MJX_DAMAGE_CACHE_DIR=off`` to switch it off). Compiling a task step takes
15–30 s on a laptop CPU; with JAX's persistent cache the second run of the same
command starts in seconds. Default location: ``$XDG_CACHE_HOME/mjx_damage/jax``
(``~/.cache/mjx_damage/jax``). A ``JAX_COMPILATION_CACHE_DIR`` the user set
already wins. The cache saves XLA compilation only: a warm run still imports
the packages and traces the step in Python (on a 2-core CPU ≈ 3 s and 5–10 s
of a 10–18 s warm ``mjx-damage eval``; ``benchmarks/compile_cache.py``).
"""

from __future__ import annotations

import os
import sys
import warnings

CPU_SCHEDULER_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
CPU_FUSION_FLAG = "--xla_cpu_use_fusion_emitters=false"
CPU_FLAGS = (CPU_SCHEDULER_FLAG, CPU_FUSION_FLAG)
# Newest jaxlib (major, minor) whose XLA still parses the flag; None: every version we support.
_LAST_JAXLIB = {CPU_SCHEDULER_FLAG: None, CPU_FUSION_FLAG: (0, 10)}


def _jaxlib_version() -> tuple[int, int] | None:
  from importlib import metadata
  try:
    major, minor = metadata.version("jaxlib").split(".")[:2]
    return int(major), int(minor)
  except (metadata.PackageNotFoundError, ValueError):
    return None


def cpu_flags(version: tuple[int, int] | None = None) -> tuple[str, ...]:
  """The :data:`CPU_FLAGS` that jaxlib ``version`` (default: the installed one) knows; XLA aborts on others."""
  version = _jaxlib_version() if version is None else version
  return tuple(f for f in CPU_FLAGS
               if _LAST_JAXLIB[f] is None or version is None or version <= _LAST_JAXLIB[f])


def _name(flag: str) -> str:
  return flag.split("=")[0]


def _off(value: str | None) -> bool:
  return value is not None and value.strip().lower() in ("0", "off", "false", "no", "")


def backends_started() -> bool:
  """True when some JAX backend already exists (then XLA_FLAGS are fixed for this process)."""
  xb = sys.modules.get("jax._src.xla_bridge")
  return bool(xb is not None and getattr(xb, "_backends", None))


def xla_flags_with_cpu_fix(flags: str, wanted: tuple[str, ...] | None = None) -> str:
  """``flags`` with each of ``wanted`` (default :func:`cpu_flags`) added, unless the user already chose a value for it."""
  for flag in cpu_flags() if wanted is None else wanted:
    if _name(flag) not in flags:
      flags = (flags + " " + flag).strip()
  return flags


def configure_xla_cpu() -> bool:
  """Add :func:`cpu_flags` to ``XLA_FLAGS``; True when the process will run with all of them.

  Warns (once, naming the variable to set) when a JAX backend started before
  :mod:`mjx_damage` was imported, since XLA reads its flags only then.
  """
  if _off(os.environ.get("MJX_DAMAGE_XLA_CPU_FIX")):
    return False
  wanted = cpu_flags()
  flags = os.environ.get("XLA_FLAGS", "")
  if all(_name(f) in flags for f in wanted):
    return all(f in flags for f in wanted)
  if backends_started():
    warnings.warn(
        "mjx_damage was imported after JAX started its backends, so it could not set "
        f"XLA_FLAGS='{' '.join(wanted)}'; batched MJX calls on CPU can deadlock without the scheduler flag"
        + (", and deep kinematic chains (the Panda) run 100× slower without the fusion-emitter one. "
           if CPU_FUSION_FLAG in wanted else ". ") +
        "Import mjx_damage first, or export that XLA_FLAGS value before starting Python.",
        RuntimeWarning, stacklevel=3)
    return False
  flags = xla_flags_with_cpu_fix(flags, wanted)
  os.environ["XLA_FLAGS"] = flags
  return all(f in flags for f in wanted)


GPU_DETERMINISM_FLAG = "--xla_gpu_deterministic_ops=true"


def deterministic_gpu_ops() -> bool:
  """True when ``XLA_FLAGS`` asks XLA for deterministic GPU kernels (:data:`GPU_DETERMINISM_FLAG`)."""
  return GPU_DETERMINISM_FLAG in os.environ.get("XLA_FLAGS", "").split()


def use_deterministic_gpu_ops(field: str = "--deterministic") -> None:
  """Add :data:`GPU_DETERMINISM_FLAG` to ``XLA_FLAGS`` so that a rerun of a GPU run repeats it bit for bit.

  Call before anything starts a JAX backend (XLA reads its flags once). Raises ValueError naming
  ``field`` when ``XLA_FLAGS`` already sets the flag to another value, RuntimeError when a backend is
  already running. Costs throughput on a GPU (module docstring); on a CPU it changes nothing.
  """
  if deterministic_gpu_ops():
    return
  flags = os.environ.get("XLA_FLAGS", "")
  if _name(GPU_DETERMINISM_FLAG) in flags:
    raise ValueError(f"{field}: XLA_FLAGS already sets {_name(GPU_DETERMINISM_FLAG)} to another value "
                     f"({flags!r}); drop it from XLA_FLAGS or leave out {field}")
  if backends_started():
    raise RuntimeError(f"{field}: JAX's backends already started, so XLA would ignore {GPU_DETERMINISM_FLAG}; "
                       "ask for it before the first computation, or export XLA_FLAGS before starting Python")
  os.environ["XLA_FLAGS"] = (flags + " " + GPU_DETERMINISM_FLAG).strip()


# --matmul-precision values: the backend's own, or full float32 (JAX's "highest" is the same)
MATMUL_PRECISIONS = ("default", "float32")


def matmul_precision() -> str:
  """JAX's precision for float32 matrix products traced now: "default" (the backend's own: TF32 on recent NVIDIA
  GPUs, float32 on a CPU), "float32" (also for JAX's synonym "highest"), or another ``jax_default_matmul_precision``
  value as JAX names it."""
  import jax

  value = jax.config.jax_default_matmul_precision
  return {None: "default", "default": "default", "highest": "float32"}.get(value, str(value))


def use_matmul_precision(value: str, field: str = "--matmul-precision") -> None:
  """Trace every program from now on with float32 matrix products at ``value`` (:data:`MATMUL_PRECISIONS`).

  The precision is fixed when a program is traced, so this may come after a backend started; programs traced
  before keep theirs. Raises ValueError naming ``field`` for another value.
  """
  if value not in MATMUL_PRECISIONS:
    raise ValueError(f"{field}: one of {', '.join(MATMUL_PRECISIONS)}, got {value!r}")
  import jax

  jax.config.update("jax_default_matmul_precision", None if value == "default" else value)


def matmul_label(precision: str | None = None) -> str:
  """How results name a matmul precision other than the default ("float32 matmuls"; "" for the default).
  ``precision``: a recorded one, or None for the one in force (:func:`matmul_precision`)."""
  precision = matmul_precision() if precision is None else precision
  return "" if precision == "default" else f"{precision} matmuls"


def flags_in_force(deterministic: bool, precision: str | None) -> str:
  """The options a training command needs to repeat this process's run beyond those it was given
  (``deterministic``: ``--deterministic`` given; ``precision``: the ``--matmul-precision`` given, or None):
  ``" --deterministic"`` when XLA_FLAGS asked for :data:`GPU_DETERMINISM_FLAG`, ``" --matmul-precision V"`` when
  JAX_DEFAULT_MATMUL_PRECISION set V (one the option refuses, if V is not in :data:`MATMUL_PRECISIONS`: a rerun
  then stops rather than run at another precision). Empty when the command says it all."""
  out = ""
  if deterministic_gpu_ops() and not deterministic:
    out += " --deterministic"
  if precision is None and matmul_precision() != "default":
    out += f" --matmul-precision {matmul_precision()}"
  return out


def cache_dir() -> str | None:
  """The persistent compilation cache directory the package uses, or None when off."""
  explicit = os.environ.get("MJX_DAMAGE_CACHE_DIR")
  if explicit is not None:
    return None if _off(explicit) else os.path.abspath(os.path.expanduser(explicit))
  if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
    return os.path.abspath(os.path.expanduser(os.environ["JAX_COMPILATION_CACHE_DIR"]))
  base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
  return os.path.join(base, "mjx_damage", "jax")


def enable_compilation_cache() -> str | None:
  """Point JAX's persistent compilation cache at :func:`cache_dir`; returns it (None: off)."""
  path = cache_dir()
  if path is None:
    return None
  import jax

  try:
    os.makedirs(path, exist_ok=True)
  except OSError as e:  # read-only home: run without the cache rather than fail
    warnings.warn(f"compilation cache disabled: cannot create {path}: {e}", RuntimeWarning, stacklevel=3)
    return None
  jax.config.update("jax_compilation_cache_dir", path)
  # Cache every compile, however short: with a time threshold, whether a small
  # program (a 0.3 s PRNG split) is written depends on the machine's load, so a
  # second run on a busy machine recompiled what a quiet one had cached.
  jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
  jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
  return path


def run_facts() -> dict:
  """When and where a benchmark ran, for its results file: UTC timestamp, JAX's first device
  (``platform:kind``), host name, CPU cores and the jax version."""
  import datetime
  import platform

  import jax

  d = jax.devices()[0]
  return {"timestamp_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y%m%dT%H%M%SZ"),
          "device": f"{d.platform}:{d.device_kind}", "host": platform.node(), "cpu_count": os.cpu_count(),
          "jax": jax.__version__}


def device_info() -> tuple[str, str]:
  """(slug, description) of JAX's first device, for results file names and headers.

  slug: ``"cpu"`` or the device kind in lower case with ``_`` (``nvidia_h100_80gb_hbm3``).
  """
  import platform

  import jax

  d = jax.devices()[0]
  kind = getattr(d, "device_kind", d.platform)
  if d.platform == "cpu":
    return "cpu", f"{platform.processor() or platform.machine()} CPU, {os.cpu_count()} cores ({kind})"
  slug = "".join(c if c.isalnum() else "_" for c in kind.lower()).strip("_")
  return slug, f"{kind} ({d.platform}, {jax.device_count()} device(s))"
