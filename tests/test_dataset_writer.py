"""benchmarks/dataset_writer.py: bad flags named before anything is written; a tiny run against a git
revision's writer produces both rows."""

import json

import pytest

from conftest import load_benchmark


@pytest.mark.parametrize("flags, named", [(["--episodes", "0"], "--episodes"), (["--repeats", "-1"], "--repeats"),
                                          (["--objects", "0"], "--objects")])
def test_bad_flags_exit_2_naming_the_flag(flags, named, capsys, tmp_path):
  with pytest.raises(SystemExit) as e:
    load_benchmark("dataset_writer").main(flags + ["--results-dir", str(tmp_path)])
  assert e.value.code == 2 and named in capsys.readouterr().err
  assert not list(tmp_path.iterdir())


def test_unknown_revision_is_named(tmp_path):
  with pytest.raises(ValueError, match="compare: git cannot show no-such-rev"):
    load_benchmark("dataset_writer").main(["--compare", "no-such-rev", "--results-dir", str(tmp_path)])


def test_tiny_run_times_both_writers(tmp_path):
  # HEAD: present in any clone, shallow ones too (the committed results compare against 18a26ff)
  load_benchmark("dataset_writer").main(["--episodes", "4", "--repeats", "1", "--objects", "4", "--compare",
                                         "HEAD", "--tag", "t", "--results-dir", str(tmp_path)])
  res = json.loads((tmp_path / "dataset_writer_t.json").read_text())
  assert [r["writer"] for r in res["rows"]] == ["this", "HEAD"]
  assert all(r["median_tr_s"] > 0 for r in res["rows"]) and res["objects"]["dataset_us"] > 0
  assert "| HEAD |" in (tmp_path / "dataset_writer_t.md").read_text()
