"""Several processes (hosts) in one run, on JAX's own distributed runtime; which devices a run uses.

``jax.distributed.initialize`` connects the processes through a coordinator
(process 0, listening at ``HOST:PORT``). From then on ``jax.devices()`` lists
every process's devices, each process owns (feeds, reads) its local ones, and
one jit-compiled program runs on all of them: XLA's collectives (NCCL on GPU,
gloo on CPU) carry the reductions between processes. The same script runs in
every process; this module holds what differs between them:

* the command-line flags (``--devices --coordinator --num-processes
  --process-id --dist-timeout --heartbeat-timeout``), checked before JAX
  starts (:func:`check`), one ``ValueError("--flag: ...")`` per mistake;
* :func:`initialize` with a bounded wait: JAX's own connect timeout ends the
  process with a C++ abort and a misleading "another task died", so a
  watchdog thread prints one line naming the flags and exits with status 2
  first;
* :func:`select_devices` (``--devices all|N``: N devices, N / processes from
  each process);
* :func:`is_main` (only process 0 writes files), :func:`to_host` (a global
  array's value on every process: the checkpoint, the metrics),
  :func:`any_process` (one stop decision for all: a SIGTERM or a time limit
  seen by one process stops all at the same iteration, else the others would
  wait in a collective the stopped one never joins).

A process that dies is noticed by the coordination service after
``--heartbeat-timeout`` seconds (one that fails with an error waits as long
at exit for the others, which are stuck in a collective it left); it then
terminates every other process with
"Terminating process because the JAX distributed service detected fatal
errors. This most likely indicates that another task died" (exit by
SIGABRT). ``--coordinator auto``: JAX's cluster auto-detection (Slurm, Open
MPI, mpi4py, Kubernetes, TPU pods) fills in address, process count and id.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import threading
import time
from typing import Optional, Sequence, Union

import jax
import numpy as np
from jax.experimental import multihost_utils

DEFAULT_TIMEOUT_S = 300  # wait for every process to connect (JAX's default)
DEFAULT_HEARTBEAT_S = 60  # a process silent this long is dead: the others are terminated


@dataclasses.dataclass(frozen=True)
class Setup:
  """Validated distributed settings. ``coordinator`` None: one process, no initialize."""

  devices: Union[str, int, None] = None  # "all", N, or None (1; all with a coordinator)
  coordinator: Optional[str] = None  # "host:port" or "auto"
  num_processes: Optional[int] = None
  process_id: Optional[int] = None
  timeout: int = DEFAULT_TIMEOUT_S  # s
  heartbeat: int = DEFAULT_HEARTBEAT_S  # s

  @property
  def multi_process(self) -> bool:
    return self.coordinator is not None

  @property
  def device_spec(self) -> Union[str, int]:
    """``--devices`` with its default filled in: 1 on one process, all across several."""
    return self.devices if self.devices is not None else ("all" if self.multi_process else 1)


def add_arguments(p, devices_default: Optional[str] = None) -> None:
  """The distributed flags on an argparse parser. ``--devices`` defaults to ``devices_default``;
  None: 1 device on one process, all with ``--coordinator`` (:attr:`Setup.device_spec`)."""
  shown = devices_default or "1; all with --coordinator"
  p.add_argument("--devices", default=devices_default, metavar="all|N",
                 help="devices the run is spread over: all, or a count (with several processes: "
                      f"N / num-processes from each) (default: {shown})")
  p.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                 help="process 0's address: start one process per host with the same value; "
                      "auto: JAX's cluster detection (Slurm, Open MPI, ...) (default: one process)")
  p.add_argument("--num-processes", type=int, default=None, help="processes in the run (with --coordinator HOST:PORT)")
  p.add_argument("--process-id", type=int, default=None,
                 help="this process, 0 .. num-processes-1 (0 writes the outputs)")
  p.add_argument("--dist-timeout", type=int, default=DEFAULT_TIMEOUT_S,
                 help="seconds to wait for every process to connect before giving up")
  p.add_argument("--heartbeat-timeout", type=int, default=DEFAULT_HEARTBEAT_S,
                 help="seconds after which a process that died (or failed) ends the others")


def parse_devices(text) -> Union[str, int, None]:
  """``--devices`` value: None, "all" or an int >= 1 (ValueError naming the flag)."""
  if text is None or text == "all":
    return text
  try:
    n = int(str(text))
  except ValueError:
    raise ValueError(f"--devices: all or a device count, got {text!r}") from None
  if n < 1:
    raise ValueError(f"--devices: must be >= 1 (or all), got {n}")
  return n


def parse_address(text: str) -> tuple[str, int]:
  """``HOST:PORT`` → (host, port); IPv6 as ``[::1]:PORT``."""
  host, sep, port = text.rpartition(":")
  host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
  if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536 or any(c.isspace() for c in host):
    raise ValueError(f"--coordinator: expected HOST:PORT (port 1-65535) or auto, got {text!r}")
  return host, int(port)


def check(devices=None, coordinator=None, num_processes=None, process_id=None,
          dist_timeout=DEFAULT_TIMEOUT_S, heartbeat_timeout=DEFAULT_HEARTBEAT_S) -> Setup:
  """The flags' values → :class:`Setup`; ``ValueError("--flag: ...")`` before JAX starts."""
  devices = parse_devices(devices)
  for flag, v in (("--dist-timeout", dist_timeout), ("--heartbeat-timeout", heartbeat_timeout)):
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
      raise ValueError(f"{flag}: must be a number of seconds >= 1, got {v!r}")
  if coordinator is None:
    if num_processes not in (None, 1) or process_id not in (None, 0):
      raise ValueError("--coordinator: --num-processes/--process-id need --coordinator HOST:PORT (or auto)")
    return Setup(devices, None, None, None, dist_timeout, heartbeat_timeout)
  if coordinator != "auto":
    parse_address(coordinator)
    if num_processes is None or process_id is None:
      raise ValueError("--num-processes: --coordinator HOST:PORT needs --num-processes and --process-id "
                       "(or --coordinator auto on a cluster JAX detects)")
  if num_processes is not None and num_processes < 1:
    raise ValueError(f"--num-processes: must be >= 1, got {num_processes}")
  if process_id is not None and not 0 <= process_id < (num_processes or sys.maxsize):
    raise ValueError(f"--process-id: must be in 0..{(num_processes or 0) - 1} (--num-processes {num_processes}), "
                     f"got {process_id}")
  if isinstance(devices, int) and num_processes and devices % num_processes:
    raise ValueError(f"--devices: {devices} devices cannot be split evenly over --num-processes {num_processes}")
  return Setup(devices, coordinator, num_processes, process_id, dist_timeout, heartbeat_timeout)


def initialize(setup: Setup, prog: str = "mjx-damage") -> None:
  """``jax.distributed.initialize`` for ``setup`` (nothing for one process); call before any JAX computation.

  Waits at most ``setup.timeout`` s for all processes; then prints one line and exits with status 2.
  """
  if not setup.multi_process:
    return
  start = time.perf_counter()

  def give_up():
    who = ("the coordinator at " + setup.coordinator if setup.process_id else "all --num-processes processes")
    print(f"{prog}: error: --coordinator: could not reach {who} within --dist-timeout {setup.timeout} s "
          f"(is every process started, with the same --coordinator and --num-processes and its own --process-id?)",
          file=sys.stderr, flush=True)
    os._exit(2)

  watchdog = threading.Timer(setup.timeout, give_up)
  watchdog.daemon = True
  watchdog.start()
  kwargs = {} if setup.coordinator == "auto" else dict(
      coordinator_address=setup.coordinator, num_processes=setup.num_processes, process_id=setup.process_id)
  try:
    # JAX's own timeout a little later than ours: our line, not its abort, is what the user reads.
    # shutdown timeout = heartbeat: a process that fails with an exception (alive, so still sending
    # heartbeats) waits at exit for the others, stuck in a collective it never joins; they all end then.
    jax.distributed.initialize(**kwargs, initialization_timeout=setup.timeout + 30,
                               heartbeat_timeout_seconds=setup.heartbeat, shutdown_timeout_seconds=setup.heartbeat)
  except (ValueError, RuntimeError) as e:  # auto-detection found no cluster, or JAX already started
    watchdog.cancel()
    raise ValueError(f"--coordinator: {' '.join(str(e).split())}") from None
  watchdog.cancel()
  print(f"distributed: process {jax.process_index()} of {jax.process_count()}, {jax.local_device_count()} local "
        f"of {jax.device_count()} device(s), connected in {time.perf_counter() - start:.1f} s", flush=True)


def select_devices(spec: Union[str, int, Sequence, None] = None) -> list:
  """The devices a run uses: "all", N (N / processes from each process, in process order), a device
  list, or None (the first device). ``ValueError("--devices: ...")`` when there are not that many."""
  if spec is None:
    return [jax.devices()[0]]
  if not isinstance(spec, (str, int)):
    return list(spec)
  spec = parse_devices(spec)
  if spec == "all":
    return list(jax.devices())
  procs = jax.process_count()
  if spec > jax.device_count():
    raise ValueError(f"--devices: {spec} requested, {jax.device_count()} available "
                     f"({jax.local_device_count()} per process x {procs} process(es))")
  if spec % procs:
    raise ValueError(f"--devices: {spec} devices cannot be split evenly over {procs} processes")
  per = spec // procs
  by_process = [[d for d in jax.devices() if d.process_index == p] for p in range(procs)]
  short = [p for p, ds in enumerate(by_process) if len(ds) < per]
  if short:
    raise ValueError(f"--devices: {spec} needs {per} per process; process {short[0]} has {len(by_process[short[0]])}")
  return [d for ds in by_process for d in ds[:per]]


def is_main() -> bool:
  """True on the process that writes files (process 0; the only one without a coordinator)."""
  return jax.process_index() == 0


def to_host(tree):
  """numpy copies of a pytree of (possibly multi-process) arrays; every process calls it (a collective)."""
  if jax.process_count() == 1:
    return jax.device_get(tree)
  return multihost_utils.process_allgather(tree, tiled=True)


def any_process(*flags: bool) -> tuple[bool, ...]:
  """Each flag true on every process when it is true on any (one collective with several processes)."""
  mine = np.asarray([bool(f) for f in flags])
  if jax.process_count() == 1:
    return tuple(bool(f) for f in mine)
  return tuple(bool(f) for f in np.any(multihost_utils.process_allgather(mine[None], tiled=True), axis=0))
