"""``mjx-damage demo``: the default job — damage-aware batched rollout of the drop scene."""

from __future__ import annotations

import time

import numpy as np

from train.cliargs import Parser, heartbeat, say_compiling


def main(argv=None) -> int:
  ap = Parser(prog="mjx-damage demo", description=__doc__ + " Prints a table; writes no file.")
  ap.add_argument("--envs", type=int, default=256, help="parallel environments")
  ap.add_argument("--seconds", type=float, default=1.0, help="simulated time per env, s")
  ap.add_argument("--max-height", type=float, default=0.12, help="highest drop above the counter, m")
  ap.add_argument("--seed", type=int, default=0)
  args = ap.parse_args(argv)
  if args.envs < 1:
    ap.error("--envs: must be >= 1")
  if not 0 < args.seconds < 1e4:
    ap.error(f"--seconds: must be in (0, 1e4), got {args.seconds}")
  if not 0 <= args.max_height < 100:
    ap.error(f"--max-height: must be in [0, 100) m, got {args.max_height}")
  if args.seed < 0:
    ap.error(f"--seed: must be >= 0, got {args.seed}")

  import jax  # imported after parsing: keeps `--help` fast
  import jax.numpy as jnp

  from mjx_damage.wrapper import DamageWrapper
  from tasks.drop import DropEnv

  env = DamageWrapper(DropEnv(min_height=0.0, max_height=args.max_height))
  steps = max(1, int(round(args.seconds / env.dt)))

  @jax.jit
  def rollout(rng):
    state = jax.vmap(env.reset)(jax.random.split(rng, args.envs))
    act = jnp.zeros((args.envs, env.action_size))
    state = jax.lax.fori_loop(0, steps, lambda _, s: jax.vmap(env.step)(s, act), state)
    return state.info["drop_height"], state.info["entity_health"], state.info["damage_episode"]["damaged"]

  print(f"demo: drop scene, {args.envs} envs x {steps} steps, device {jax.default_backend()} x "
        f"{jax.device_count()}; writes no file", flush=True)
  say_compiling({"cpu": 20, "gpu": 20}, jax.default_backend())
  t0 = time.perf_counter()
  with heartbeat("demo"):
    compiled = rollout.lower(jax.random.PRNGKey(args.seed)).compile()
  t1 = time.perf_counter()
  height, health, damaged = jax.block_until_ready(compiled(jax.random.PRNGKey(args.seed)))
  t2 = time.perf_counter()
  height, health = np.asarray(height), np.asarray(health)
  names = env.entity_names
  print(f"drop scene: {args.envs} envs x {steps} control steps ({env.dt * 1e3:.0f} ms, "
        f"{env.n_substeps} physics substeps each), damage at every substep")
  print(f"compile {t1 - t0:.1f} s, run {t2 - t1:.2f} s = "
        f"{args.envs * steps * env.n_substeps / (t2 - t1):,.0f} physics steps/s\n")
  edges = np.linspace(0.0, args.max_height, 7)
  header = f"{'drop height (m)':>17} {'envs':>5} " + " ".join(f"{n + ' health':>14}" for n in names)
  print(header)
  for lo, hi in zip(edges[:-1], edges[1:]):
    sel = (height >= lo) & (height <= hi)
    if not sel.any():
      continue
    cols = " ".join(f"{health[sel, i].mean():>14.1f}" for i in range(len(names)))
    print(f"{lo:>7.2f} - {hi:<7.2f} {int(sel.sum()):>5} {cols}")
  print("\nall envs: " + ", ".join(f"{n} mean {health[:, i].mean():.1f} min {health[:, i].min():.1f}"
                                  for i, n in enumerate(names)))
  print(f"zero-damage episodes: {100 * (1 - np.asarray(damaged).mean()):.0f} %")
  return 0
