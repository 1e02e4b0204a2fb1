"""benchmarks/panda_arm_damage.py: bad arguments stop before anything compiles; the arm/hand split and the
per-policy summary from final link health (no rollout here)."""

import numpy as np
import pytest
from conftest import load_benchmark

P = load_benchmark("panda_arm_damage")

LINKS = ("plate/plate", "agent/panda_link0", "agent/panda_link1", "agent/panda_link7", "agent/panda_hand",
         "agent/panda_finger_left", "agent/panda_finger_right")
ENTITY = np.array([0, 1, 1, 1, 1, 1, 1])


@pytest.mark.parametrize("argv, message", [
    (["--tasks", "no_such_task"], "tasks: unknown task(s) no_such_task"),
    (["--tasks", "pick_egg", "pick_egg"], "tasks: listed twice: pick_egg"),
    (["--episodes", "0"], "episodes: must be a positive integer"),
    (["--threshold", "nan"], "threshold: must be in (0, 100]"),
    (["--threshold", "150"], "threshold: must be in (0, 100]"),
])
def test_bad_arguments_name_the_field(argv, message, capsys):
  with pytest.raises(SystemExit) as e:
    P.main(argv)
  assert e.value.code == 2 and message in capsys.readouterr().err


def test_default_tasks_are_those_the_panda_runs():
  chosen = P.check_args(P.build_parser().parse_args([]))
  assert chosen == P.tasks.select(None, "panda") and "navigate_and_pick" in chosen  # on its mobile base


def test_arm_links_are_the_panda_links_of_the_agent():
  arm, hand = P.arm_and_hand(LINKS, ENTITY, ("plate", "agent"))
  assert arm == [1, 2, 3] and hand == [4, 5, 6]


def test_summary_counts_episodes_with_a_damaged_arm_or_hand():
  arm, hand = P.arm_and_hand(LINKS, ENTITY, ("plate", "agent"))
  final = np.full((4, len(LINKS)), 100.0)
  final[0, 3] = 80.0  # episode 0: link7 hit
  final[1, 3] = 99.9  # above the threshold: not damaged
  final[2, 5] = 50.0  # episode 2: a finger only
  s = P.summarise(final, np.array([True, True, False, True]), LINKS, arm, hand, 99.5)
  assert s["arm_damaged"] == 0.25 and s["hand_damaged"] == 0.25 and s["completion"] == 0.75
  assert s["worst_arm_link"] == "panda_link7" and abs(s["worst_arm_link_health"] - (80 + 99.9 + 200) / 4) < 1e-9


def test_a_task_counts_only_when_unsafe_hits_the_arm_and_safe_never_does():
  row = lambda task, safe, unsafe: {"task": task, "policies": {"safe": {"arm_damaged": safe},  # noqa: E731
                                                               "unsafe": {"arm_damaged": unsafe}}}
  results = [row("a", 0.0, 0.5), row("b", 0.1, 0.9), row("c", 0.0, 0.0)]
  assert P.arm_only_tasks(results) == ["a"]
