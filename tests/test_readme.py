"""README code blocks marked ``<!-- runnable … -->`` run as written (issue 23 item 6).

A fenced ```python or ```bash block directly after a line starting with
``<!-- runnable`` is extracted and run from an empty temporary directory with
this checkout on ``PYTHONPATH`` and Python's default warning filters (what a user sees);
it must exit 0 and print no warning. Blocks
without the marker are illustrations (they name files of the reader's own, or
sizes meant for a GPU).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARK = "<!-- runnable"
_BLOCK = re.compile(r"^(<!-- runnable[^\n]*-->)\n```(python|bash)\n(.*?)^```", re.M | re.S)


def runnable_blocks(text: str) -> list[tuple[str, str]]:
  """(language, code) of every block right after a runnable marker."""
  return [(m.group(2), m.group(3)) for m in _BLOCK.finditer(text)]


def _readme() -> str:
  with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
    return f.read()


def test_every_marker_is_followed_by_a_block():
  text = _readme()
  assert text.count(MARK) == len(runnable_blocks(text)) >= 1


def test_extractor_reads_only_marked_blocks():
  text = "```python\nskip()\n```\n<!-- runnable -->\n```bash\necho hi\n```\n"
  assert runnable_blocks(text) == [("bash", "echo hi\n")]


@pytest.mark.slow
@pytest.mark.parametrize("i", range(len(runnable_blocks(_readme()))))
def test_readme_block_runs(i, tmp_path):
  lang, code = runnable_blocks(_readme())[i]
  cmd = [sys.executable, "-c", code] if lang == "python" else ["bash", "-euo", "pipefail", "-c", code]
  env = dict(os.environ, PYTHONPATH=ROOT, JAX_PLATFORMS="cpu",
             PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
  p = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
  assert p.returncode == 0, f"block {i} ({lang}):\n{code}\n{p.stderr[-3000:]}"
  assert "warning" not in p.stderr.lower(), p.stderr[-3000:]
