"""The periodic line long commands print: it comes at the set rhythm while the block runs and stops
with the block (also when the block raises)."""

import io
import time

import pytest

from train.cliargs import heartbeat


def test_beats_while_running_and_stops_after():
  out = io.StringIO()
  with heartbeat("eval", every=0.05, stream=out):
    time.sleep(0.3)
  lines = out.getvalue().splitlines()
  assert 2 <= len(lines) <= 7 and all(line.startswith("eval: still working, ") for line in lines)
  n = len(lines)
  time.sleep(0.2)
  assert len(out.getvalue().splitlines()) == n


def test_stops_when_the_block_raises():
  out = io.StringIO()
  with pytest.raises(KeyboardInterrupt):
    with heartbeat("train", every=0.05, stream=out):
      raise KeyboardInterrupt
  n = len(out.getvalue().splitlines())
  time.sleep(0.2)
  assert len(out.getvalue().splitlines()) == n
