"""The newer task designs without compiling: entities, sizes, descriptions, designed contact slots.

Their rollouts (random and extreme actions, scripted safe/unsafe) are the task contract's
(tests/test_task_contract.py, one compile per task); 256-episode separation is
benchmarks/scripted_policies.py's job.
"""

import pytest
from mujoco import mjx

import tasks

# task -> (entities, observation size, horizon, modality prefix, most contact slots)
DESIGNS = {
    "serve_pastry": (("pastry", "plate", "agent"), 21, None, "mechanical:", 56),
    "pick_up_scrub": (("scrub_brush", "wineglass", "agent"), 21, None, "mechanical:", 56),
    "attach_camera": (("camera", "tripod", "agent"), 21, None, "mechanical:", 56),
    "dishes_to_sink": (("plate", "cup", "agent"), 20, 250, "mechanical:", None),
    "place_in_microwave": (("dish", "agent"), 18, 150, "mechanical:", None),
}


@pytest.mark.parametrize("name", sorted(DESIGNS))
def test_design_without_compiling(name):
  entities, obs, horizon, modality, slots = DESIGNS[name]
  env = tasks.make(name)
  assert env.entity_names == entities and env.observation_size == obs and env.action_size == 4, name
  d = tasks.describe(name)
  assert d["damage_modality"].startswith(modality) and tuple(d["tracked_entities"]) == entities
  if horizon is not None:
    assert d["horizon"] == horizon
  if slots is not None:  # designed contact pairs only
    assert mjx.make_data(env.unwrapped.sys)._impl.contact.dist.shape[0] <= slots, name


def test_unknown_policy_style_is_refused():
  with pytest.raises(ValueError, match="style"):
    tasks.task_class("serve_pastry").policy(tasks.make("serve_pastry").unwrapped, "reckless")
