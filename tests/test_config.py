"""Parameters as data and config validation: every malformed config names its field."""

import copy

import mujoco
import numpy as np
import pytest
import yaml

import mjx_damage as md
from tasks.drop import load_scene

GOOD = {
    "entities": {
        "plate": {"params": "plate", "bodies": ["plate"]},
        "mug": {"params": "coffee_cup", "bodies": ["mug"], "mechanical": {"threshold": 120.0},
                "links": {"mug": {"mechanical": {"scale": 3.0}}}},
    }
}


@pytest.fixture(scope="module")
def model():
  return load_scene()


def test_object_params_tables():
  p = md.object_params("agent")
  assert (p.mechanical.alpha, p.mechanical.beta, p.mechanical.threshold, p.mechanical.scale) == (0.01, 1.0, 70.0, 0.2)
  assert (p.thermal.t_hot, p.thermal.t_cold, p.thermal.scale) == (40.0, -20.0, 1.0)
  assert (p.fluid.threshold, p.fluid.scale) == (10.0, 10.0)
  assert md.object_params("plate").thermal is None
  with pytest.raises(ValueError, match="unknown object 'teapot'.*known objects: agent"):
    md.object_params("teapot")


def test_resolve_overrides_and_arrays(model):
  b = md.bind(model, GOOD)
  assert b.entity_names == ("plate", "mug")
  assert b.link_names == ("plate/plate", "mug/mug")
  p = b.params
  np.testing.assert_allclose(p.mech_threshold, [50.0, 120.0])
  np.testing.assert_allclose(p.mech_scale, [10.0, 3.0])
  assert p.alpha.dtype == np.float32 and p.tau.shape == ()
  assert GOOD["entities"]["mug"]["mechanical"] == {"threshold": 120.0}  # input untouched


def test_yaml_config(model, tmp_path):
  f = tmp_path / "cfg.yaml"
  f.write_text(yaml.safe_dump(GOOD, sort_keys=False))
  assert md.bind(model, str(f)).link_names == ("plate/plate", "mug/mug")


def test_track_subset(model):
  cfg = dict(GOOD, track=["mug"])
  b = md.bind(model, cfg)
  assert b.entity_names == ("mug",)
  assert b.geom_link[model.geom("plate").id] == -1


def _with(path, value):
  cfg = copy.deepcopy(GOOD)
  node = cfg
  for k in path[:-1]:
    node = node[k]
  if value is KeyError:
    del node[path[-1]]
  else:
    node[path[-1]] = value
  return cfg


BAD = [
    (_with(["entities", "plate", "bodies"], ["no_such_body"]), r"entities\.plate\.bodies\[0\]: unknown body 'no_such_body'"),
    (_with(["entities", "plate", "params"], "teapot"), r"entities\.plate\.params: unknown object 'teapot'"),
    (_with(["entities", "plate", "mechanical"], {"threshold": -1.0}), r"entities\.plate\.mechanical\.threshold: must be >= 0"),
    (_with(["entities", "plate", "mechanical"], {"scale": float("nan")}), r"entities\.plate\.mechanical\.scale: must be finite"),
    (_with(["entities", "plate", "thermal"], {"t_hot": 10.0, "t_cold": 20.0, "scale": 1.0}), r"entities\.plate\.thermal\.t_cold: must be < t_hot"),
    (_with(["entities", "plate", "fluid"], {"threshold": 5.0}), r"entities\.plate\.fluid: no table row .*missing scale"),
    (_with(["entities", "plate", "mechanical"], {"treshold": 5.0}), r"entities\.plate\.mechanical\.treshold: unknown key"),
    (_with(["entities", "plate", "mechanical"], {"alpha": "1.0"}), r"entities\.plate\.mechanical\.alpha: expected a number, got str"),
    (_with(["entities", "plate", "bodies"], "plate"), r"entities\.plate\.bodies: expected a non-empty list"),
    ({"entities": {"plate": {}, "mug": {"params": "default", "bodies": ["plate"]}}}, r"entities\.mug\.bodies\[0\]: body 'plate' already belongs to entity 'plate'"),
    (dict(GOOD, track=[]), r"track: empty tracking set"),
    (dict(GOOD, track=["bowl"]), r"track\[0\]: unknown entity 'bowl'"),
    ({"entities": {}}, r"entities: empty"),
    (dict(GOOD, tau=0.0), r"tau: must be > 0"),
    (dict(GOOD, colour="red"), r"colour: unknown key"),
    (_with(["entities", "mug", "links"], {"plate": {}}), r"entities\.mug\.links\.plate: not one of this entity's bodies"),
    (_with(["entities", "plate", "mechanical"], None), r"entities\.plate\.mechanical: mechanical damage cannot be switched off"),
    (_with(["entities", "plate"], ["plate"]), r"entities\.plate: expected a mapping"),
]


@pytest.mark.parametrize("cfg,match", BAD, ids=[m.split(":")[0].replace("\\", "") for _, m in BAD])
def test_malformed_config_names_the_field(model, cfg, match):
  with pytest.raises(ValueError, match=match):
    md.bind(model, cfg)


def test_missing_yaml_file(model):
  with pytest.raises(ValueError, match="config: file not found"):
    md.bind(model, "/nonexistent/damage.yaml")


def test_fragility_scales_thresholds_and_rates(model):
  p = md.bind(model, GOOD).params
  q = p.with_fragility(2.0)
  np.testing.assert_allclose(q.mech_threshold, p.mech_threshold / 2)
  np.testing.assert_allclose(q.mech_scale, p.mech_scale * 2)
