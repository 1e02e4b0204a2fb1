"""train.curate: episode and datapoint health filters on hand-made datasets with known answers."""

import numpy as np
import pytest

from mjx_damage import data as D
from train import curate as C


def dataset(health_egg, lengths, success=None, labels=None):
  """Episodes whose egg health per step is given (agent stays at 100); everything else zeros."""
  h = np.asarray(health_egg, np.float32)
  e, t = h.shape
  z = np.zeros((e, t), np.float32)
  return D.build(
      env_name="pick_egg", obs={"state": np.arange(e * t, dtype=np.float32).reshape(e, t, 1)},
      actions=np.zeros((e, t, 4)), rewards=z, states=np.zeros((e, t, 2)),
      health={"egg": h, "agent": np.full((e, t), 100.0)}, damage={k: z for k in D.DAMAGE_KINDS}, cost=z,
      lengths=lengths, success=np.ones(e, bool) if success is None else success, safe=np.ones(e, bool),
      labels=labels, label_names=("careful", "careless"))


def test_filter_episodes_drops_any_step_below_threshold():
  ds = dataset([[100, 100, 100, 100],   # intact
                [100, 96, 95, 95],      # exactly 95: kept
                [100, 94.9, 94.9, 94.9],  # below: dropped
                [100, 100, 50, 0]],     # below only after its end (length 2): kept
               lengths=[4, 4, 4, 2])
  out = C.filter_episodes(ds, min_health=95)
  np.testing.assert_array_equal(out.obs["state"][:, 0, 0], [0, 4, 12])
  assert out.num_episodes == 3
  with pytest.raises(ValueError, match=r"filter_episodes\(min_health=101\)|min_health: must be"):
    C.filter_episodes(ds, min_health=101)


def test_filter_episodes_empty_result_is_an_error():
  ds = dataset([[90, 80]], lengths=[2])
  with pytest.raises(ValueError, match=r"filter_episodes\(min_health=95\): no data left"):
    C.filter_episodes(ds, min_health=95)


def test_window_damage_and_filter_datapoints():
  # egg loses 3 at step 2 and 4 at step 5 (health after each step)
  h = [[100, 100, 97, 97, 97, 93, 93, 93]]
  ds = dataset(h, lengths=[8])
  w = C.window_damage(ds, horizon=3)
  # window t..t+2: t=0 sees step 2 (3), t=3 sees step 5 (4), t=4..5 step 5, t=6..7 none
  np.testing.assert_allclose(w[0], [3, 3, 3, 4, 4, 4, 0, 0])
  out = C.filter_datapoints(ds, horizon=3, max_damage=3.5)
  np.testing.assert_array_equal(out.keep[0], [1, 1, 1, 0, 0, 0, 1, 1])
  out = C.filter_datapoints(ds, horizon=8, max_damage=5)
  np.testing.assert_array_equal(out.keep[0], [0, 0, 0, 1, 1, 1, 1, 1])  # 7 lost over steps 0..5
  assert out.num_episodes == 1 and D.num_transitions(out) == 5
  with pytest.raises(ValueError, match=r"filter_datapoints\(horizon=8, max_damage=1\): no data left"):
    C.filter_datapoints(dataset([[98, 96]], lengths=[2]), horizon=8, max_damage=1)
  with pytest.raises(ValueError, match="horizon: must be an int >= 1"):
    C.filter_datapoints(ds, horizon=0)


def test_datapoint_window_stops_at_episode_end():
  # length 3: the large loss at step 4 lies in the padding and must not count
  ds = dataset([[100, 100, 100, 100, 0]], lengths=[3])
  out = C.filter_datapoints(ds, horizon=8, max_damage=0)
  np.testing.assert_array_equal(out.keep[0], [1, 1, 1, 0, 0])


def test_successful_and_with_label():
  ds = dataset([[100] * 3] * 4, lengths=[3] * 4, success=[True, False, True, True], labels=[0, 0, 1, 1])
  assert C.successful(ds).num_episodes == 3
  careless = C.with_label(ds, "careless")
  np.testing.assert_array_equal(careless.obs["state"][:, 0, 0], [6, 9])
  with pytest.raises(ValueError, match="label: 'lazy' not in this dataset"):
    C.with_label(ds, "lazy")
