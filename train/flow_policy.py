"""Flow-matching policy with action chunking (the paper's IL policy, low-dimensional state version).

Model: a velocity field ``v_θ(x, τ, o)`` over action chunks ``x ∈ R^{H×A}``
(H = 8 steps, the paper's chunk), an MLP on [normalised obs; x; sinusoidal
features of τ] (the paper uses a π0-style transformer on segmentation images;
with low-dimensional state an MLP suffices and trains in seconds).

Training (conditional flow matching, rectified-flow path): for a kept step t
of a demo the target chunk is ``x₁ = actions[t : t+H]`` (past the episode's
end the last action repeats), ``x₀ ~ N(0, I)``, ``τ ~ Beta(1.5, 1)`` (paper),
``x_τ = (1−τ)x₀ + τx₁``, loss ``‖v_θ(x_τ, τ, o) − (x₁ − x₀)‖²``. AdamW 3e-4,
weight decay 1e-3, gradient clip 5 (the paper's table). Seeds vmapped, one jit
(:func:`train.imitation.fit`).

Acting: K = 16 Euler steps give a chunk, starting from ``temperature`` × noise
(default 0: from the noise's mean, a deterministic policy: sampled starts
replay the operators' hand tremor that the demonstrations contain, which the
closed-loop scripts corrected but a precise grasp does not forgive; compare
with ``benchmarks/il_study.py --temperature 1``). The policy executes its
FIRST action only and re-plans at the next step (receding horizon). That keeps
``policy(state, rng) -> action`` stateless, so the project's evaluator runs it
unchanged; executing whole chunks open-loop would need a chunk buffer in the
env state, which the evaluator does not carry.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mjx_damage import data as D
from train import imitation as IL
from train.evaluate import parametrized_policy

CHUNK = 8
FLOW_STEPS = 16
TIME_FEATURES = 16
TEMPERATURE = 0.0


def time_features(tau: jax.Array) -> jax.Array:
  """Sinusoidal features of τ ∈ [0, 1], f32[..., TIME_FEATURES]."""
  freqs = jnp.exp(jnp.linspace(0.0, jnp.log(100.0), TIME_FEATURES // 2))
  ang = tau[..., None] * freqs
  return jnp.concatenate([jnp.sin(ang), jnp.cos(ang)], axis=-1)


class VelocityMLP(nn.Module):
  """(obs f32[..., D] normalised, x f32[..., H·A], τ f32[...]) → velocity f32[..., H·A]."""

  out_size: int
  hidden: Sequence[int] = (512, 512, 512)

  @nn.compact
  def __call__(self, obs, x, tau):
    h = jnp.concatenate([obs, x, time_features(tau)], axis=-1)
    for w in self.hidden:
      h = nn.silu(nn.Dense(w)(h))
    return nn.Dense(self.out_size)(h)


class FlowResult(NamedTuple):
  """params: {"net", "norm"} with a leading seed axis; losses f32[S, steps]; shapes."""

  params: dict
  losses: jax.Array
  action_size: int
  chunk: int
  hidden: tuple


def action_chunks(ds: D.Dataset, chunk: int = CHUNK) -> dict:
  """Training examples: for every kept step, obs f32[N, D] and actions[t : t+chunk] f32[N, chunk, A]."""
  tr = IL.transitions_of(ds)
  e, t = tr["episode"], tr["t"]
  lengths = np.asarray(ds.lengths)
  steps = np.minimum(t[:, None] + np.arange(chunk)[None, :], lengths[e][:, None] - 1)
  acts = np.asarray(ds.actions)[e[:, None], steps]
  return {"obs": tr["obs"][IL.OBS_KEY].astype(np.float32), "chunks": acts.astype(np.float32)}


def train_flow(ds: D.Dataset, seeds: Sequence[int] = (0,), steps: int = 4000, batch: int = 256,
               lr: float = 3e-4, chunk: int = CHUNK, hidden: Sequence[int] = (512, 512, 512)) -> FlowResult:
  """Fit a :class:`VelocityMLP` per seed to the action chunks of ``ds``."""
  if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
    raise ValueError(f"chunk: must be an int >= 1, got {chunk!r}")
  ex = action_chunks(ds, chunk)
  a = ex["chunks"].shape[-1]
  norm = IL.normalizer(ex["obs"])
  net = VelocityMLP(chunk * a, tuple(hidden))

  def init(key):
    return net.init(key, jnp.zeros((ex["obs"].shape[-1],)), jnp.zeros((chunk * a,)), jnp.zeros(()))

  def loss(params, b, key):
    k0, kt = jax.random.split(key)
    x1 = b["chunks"].reshape(b["chunks"].shape[0], -1)
    x0 = jax.random.normal(k0, x1.shape)
    tau = jax.random.beta(kt, 1.5, 1.0, (x1.shape[0],))
    xt = (1.0 - tau[:, None]) * x0 + tau[:, None] * x1
    v = net.apply(params, IL.normalize(norm, b["obs"]), xt, tau)
    return jnp.mean(jnp.square(v - (x1 - x0)))

  opt = optax.chain(optax.clip_by_global_norm(5.0), optax.adamw(lr, weight_decay=1e-3))
  res = IL.fit(init, loss, ex, seeds, steps, batch, opt)
  s = res.losses.shape[0]
  norm_s = jax.tree.map(lambda x: jnp.broadcast_to(x, (s,) + x.shape), norm)
  return FlowResult({"net": res.params, "norm": norm_s}, res.losses, int(a), chunk, tuple(hidden))


def sample_chunk(net: VelocityMLP, params, obs, rng, action_size: int, chunk: int,
                 flow_steps: int = FLOW_STEPS, temperature: float = 1.0) -> jax.Array:
  """An action chunk f32[chunk, A] for one observation: Euler integration of the flow from noise.

  ``temperature`` scales the initial noise (0: start at the noise's mean, a deterministic policy).
  """
  o = IL.normalize(params["norm"], obs)
  x = temperature * jax.random.normal(rng, (chunk * action_size,))
  dt = 1.0 / flow_steps

  def body(x, i):
    return x + dt * net.apply(params["net"], o, x, i * dt), None

  x, _ = jax.lax.scan(body, x, jnp.arange(flow_steps, dtype=jnp.float32))
  return x.reshape(chunk, action_size)


def flow_apply(action_size: int, chunk: int = CHUNK, hidden: Sequence[int] = (512, 512, 512),
               flow_steps: int = FLOW_STEPS, temperature: float = TEMPERATURE):
  """``apply(params, state, rng) -> action f32[A]``: the first action of a fresh chunk (receding horizon).

  ``temperature=None``: read it from ``params["temperature"]`` (f32[]), so one compiled evaluator runs
  any temperature (``benchmarks/il_study.py`` picks one per regime on validation episodes).
  """
  net = VelocityMLP(chunk * action_size, tuple(hidden))

  def apply(params, state, rng):
    temp = params["temperature"] if temperature is None else temperature
    c = sample_chunk(net, params, state.obs, rng, action_size, chunk, flow_steps, temp)
    return jnp.clip(c[0], -1.0, 1.0)

  return apply


def with_temperature(params, temperature: float):
  """One seed's ``params`` with the sampling ``temperature`` a ``flow_apply(temperature=None)`` reads."""
  return {**params, "temperature": jnp.float32(temperature)}


def parse_temperatures(text: str) -> list[float]:
  """Comma-separated sampling temperatures, each in [0, 100); ``ValueError`` (without the field's name,
  which the caller adds) otherwise, NaN included."""
  try:
    temps = [float(t) for t in text.split(",") if t.strip()]
  except ValueError:
    raise ValueError(f"comma-separated numbers in [0, 100), got {text!r}") from None
  if not temps or not all(0.0 <= t < 100.0 for t in temps):
    raise ValueError(f"comma-separated numbers in [0, 100), got {text!r}")
  return temps


def flow_policy(res: FlowResult, seed_index: int = 0, flow_steps: int = FLOW_STEPS,
                temperature: float = TEMPERATURE):
  """Seed ``seed_index``'s policy ``policy(state, rng) -> action`` (weights passed to the evaluator as data)."""
  apply = flow_apply(res.action_size, res.chunk, res.hidden, flow_steps, temperature)
  return parametrized_policy(apply, IL.seed_params(res.params, seed_index))
