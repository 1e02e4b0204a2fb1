"""benchmarks/record_throughput.py refuses bad flags before building or compiling anything."""

import types

import pytest

from conftest import load_benchmark


@pytest.mark.parametrize("flags, named", [
    (["--tasks", "no_such_task"], "--tasks"), (["--operator", "sloppy"], "--operator"),
    (["--episodes", "0"], "--episodes"), (["--chunk", "-1"], "--chunk"),
    (["--steady-episodes", "300"], "--steady-episodes"), (["--robot", "no_such_robot"], "--robot")])
def test_bad_flags_exit_2_naming_the_flag(flags, named, capsys):
  with pytest.raises(SystemExit) as e:
    load_benchmark("record_throughput").main(flags)
  assert e.value.code == 2
  assert named in capsys.readouterr().err


def test_the_streamed_rate_is_one_chunk_per_interval_between_arrivals(monkeypatch, tmp_path):
  # A fake clock: recording a chunk takes 0.25 s, writing one 1 s (serial here). The steady cycle is then
  # 1.25 s per chunk of 80 transitions; the old rate (time to the file's close) gave 3 × 80 / 4.75 s.
  mod = load_benchmark("record_throughput")
  clock = [0.0]
  monkeypatch.setattr(mod, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))

  def chunks():
    for _ in range(4):
      clock[0] += 0.25
      yield "chunk"

  def save_chunks(path, stream):
    for _ in stream:
      clock[0] += 1.0

  monkeypatch.setattr(mod.D, "save_chunks", save_chunks)
  monkeypatch.setattr(mod.D, "num_transitions", lambda ds: 80)
  r = mod.stream_rate(chunks, str(tmp_path / "x.hdf5"), episodes=4, chunk=1)
  assert r["chunks"] == 4
  assert r["transitions_per_s"] == pytest.approx(80 / 1.25)
  assert r["total_s"] == pytest.approx(5.0) and r["last_write_s"] == pytest.approx(1.0)
  one = mod.stream_rate(lambda: iter(["chunk"]), str(tmp_path / "y.hdf5"), episodes=1, chunk=1)
  assert one["transitions_per_s"] is None
