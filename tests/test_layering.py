"""The import layers of docs/ARCHITECTURE.md, enforced.

``mjx_damage`` (core; its ``backends`` only produce link signals) ← ``tasks`` ←
``train`` ← ``apps``: a module imports only from its own layer or below, and no
two modules import each other, directly or around a loop. Every ``import``
statement counts, function-local ones included (so a local import cannot hide
a cycle); only imports under ``if TYPE_CHECKING:`` are skipped (annotations,
never executed). The scan reads the source with :mod:`ast`; nothing is imported.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAYERS = ("mjx_damage", "tasks", "train", "apps")  # bottom → top
BACKENDS = "mjx_damage.backends"
# What a backend may not import besides the layers above the core: the step that
# composes backends (physics), the env and wrapper built on that step.
STEP_MODULES = ("mjx_damage.physics", "mjx_damage.warp_step", "mjx_damage.env", "mjx_damage.wrapper")
OUTSIDE = ("benchmarks", "tests")  # scripts and tests sit on top; no package imports them
# The core modules that may import a backend: the package (its public names), the
# steps that drive a simulator (physics: MJX; warp_step: MJX on Warp; native, native_batch: MuJoCo), and binding's
# re-export of contact_forces for callers of its old path (drop it once
# wrapper.py imports from mjx_damage.backends.mjx_jax).
# the wrapper reads contacts itself for foreign envs (damage once per env step)
BACKEND_USERS = ("mjx_damage", "mjx_damage.physics", "mjx_damage.warp_step", "mjx_damage.native",
                 "mjx_damage.native_batch", "mjx_damage.wrapper")


def discover(root: str, packages=LAYERS) -> dict[str, str]:
  """Module name → file path of every ``.py`` file in ``packages`` under ``root``."""
  mods = {}
  for pkg in packages:
    base = os.path.join(root, pkg)
    for dirpath, dirnames, files in os.walk(base):
      dirnames[:] = [d for d in dirnames if d != "__pycache__"]
      for f in files:
        if f.endswith(".py"):
          rel = os.path.relpath(os.path.join(dirpath, f), root)[:-3].split(os.sep)
          if rel[-1] == "__init__":
            rel = rel[:-1]
          mods[".".join(rel)] = os.path.join(dirpath, f)
  return mods


def _is_type_checking(node: ast.If) -> bool:
  t = node.test
  return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
      isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def imported_names(path: str, module: str, is_package: bool) -> list[tuple[str, int]]:
  """(absolute dotted name, line) of every import in the file; ``from a import b`` gives ``a.b``
  (which :func:`import_graph` resolves to module ``a.b``, or to ``a`` when ``b`` is a name in it)."""
  tree = ast.parse(open(path, encoding="utf-8").read(), path)
  out = []

  def visit(node):
    if isinstance(node, ast.If) and _is_type_checking(node):
      for child in node.orelse:
        visit(child)
      return
    if isinstance(node, ast.Import):
      out.extend((a.name, node.lineno) for a in node.names)
    elif isinstance(node, ast.ImportFrom):
      if node.level:
        parts = module.split(".")
        base = parts if is_package else parts[:-1]
        base = base[: len(base) - (node.level - 1)]
        src = ".".join(base + ([node.module] if node.module else []))
      else:
        src = node.module
      out.extend((f"{src}.{a.name}" if a.name != "*" else src, node.lineno) for a in node.names)
    for child in ast.iter_child_nodes(node):
      visit(child)

  visit(tree)
  return out


def import_graph(root: str, packages=LAYERS) -> tuple[dict, dict]:
  """(modules, edges): edges[m] = {target module: first line}; targets are modules of ``packages``
  (``from pkg import name`` points at ``pkg.name`` when that is a module, else at ``pkg``)."""
  mods = discover(root, packages)
  edges = {}
  for m, path in mods.items():
    is_pkg = path.endswith("__init__.py")
    targets = {}
    for name, line in imported_names(path, m, is_pkg):
      while name and name not in mods:  # longest prefix that is one of our modules
        name = name.rpartition(".")[0]
      if name and name != m:
        targets.setdefault(name, line)
    edges[m] = targets
  return mods, edges


def _layer(module: str) -> str:
  return module.split(".")[0]


def layer_violations(root: str, packages=LAYERS) -> list[str]:
  mods, edges = import_graph(root, packages)
  bad = []
  for m, targets in sorted(edges.items()):
    rank = packages.index(_layer(m))
    for t, line in sorted(targets.items()):
      where = f"{os.path.relpath(mods[m], root)}:{line}"
      if packages.index(_layer(t)) > rank:
        bad.append(f"{where}: {m} ({_layer(m)}) imports {t} ({_layer(t)}), a layer above it")
      if t.startswith(BACKENDS + ".") and not m.startswith(BACKENDS + ".") and _layer(m) == "mjx_damage" \
          and m not in BACKEND_USERS:
        bad.append(f"{where}: core module {m} imports backend {t} (only {', '.join(BACKEND_USERS)} may)")
      if m.startswith(BACKENDS + "."):
        if t.startswith(BACKENDS + ".") and t != m:
          bad.append(f"{where}: backend {m} imports another backend, {t}")
        if t in STEP_MODULES:
          bad.append(f"{where}: backend {m} imports the step layer ({t}); a backend only produces LinkSignals")
  # Nothing in the packages imports scripts or tests.
  for m, path in sorted(mods.items()):
    for name, line in imported_names(path, m, path.endswith("__init__.py")):
      if name.split(".")[0] in OUTSIDE:
        bad.append(f"{os.path.relpath(path, root)}:{line}: {m} imports {name}")
  return bad


def import_cycles(root: str, packages=LAYERS) -> list[list[str]]:
  """Strongly connected components of more than one module (Tarjan), each sorted."""
  _, edges = import_graph(root, packages)
  index, low, on, stack, sccs = {}, {}, set(), [], []
  counter = [0]
  sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))

  def strong(v):
    index[v] = low[v] = counter[0]
    counter[0] += 1
    stack.append(v)
    on.add(v)
    for w in edges.get(v, {}):
      if w not in index:
        strong(w)
        low[v] = min(low[v], low[w])
      elif w in on:
        low[v] = min(low[v], index[w])
    if low[v] == index[v]:
      comp = []
      while True:
        w = stack.pop()
        on.discard(w)
        comp.append(w)
        if w == v:
          break
      if len(comp) > 1:
        sccs.append(sorted(comp))

  for v in sorted(edges):
    if v not in index:
      strong(v)
  return sccs


# --- the repository -------------------------------------------------------------

def test_every_package_is_scanned():
  mods, edges = import_graph(ROOT)
  for pkg in LAYERS + (BACKENDS, BACKENDS + ".mjx_jax"):
    assert pkg in mods, f"{pkg} not found under {ROOT}"
  assert sum(len(t) for t in edges.values()) > 100  # the scan sees the real imports


def test_imports_flow_one_way():
  bad = layer_violations(ROOT)
  assert not bad, "layering violations:\n" + "\n".join(bad)


def test_no_import_cycles():
  cycles = import_cycles(ROOT)
  assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


# --- the checker catches what it should ---------------------------------------------

def _tree(tmp_path, files: dict) -> str:
  for rel, text in files.items():
    p = tmp_path / rel
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(textwrap.dedent(text))
  for pkg in LAYERS + ("mjx_damage/backends",):
    init = tmp_path / pkg / "__init__.py"
    if not init.exists():
      init.parent.mkdir(parents=True, exist_ok=True)
      init.write_text("")
  return str(tmp_path)


def test_checker_flags_planted_violations(tmp_path):
  root = _tree(tmp_path, {
      "mjx_damage/core.py": "def f():\n  import tasks.thing  # local imports count\n",
      "mjx_damage/backends/a.py": "from mjx_damage import physics\nfrom . import b\n",
      "mjx_damage/backends/b.py": "",
      "mjx_damage/physics.py": "",
      "mjx_damage/health.py": "from mjx_damage.backends import b\n",
      "tasks/thing.py": "from train.loop import run\n",
      "train/loop.py": "from apps import cli\nfrom ..train import other\n",
      "train/other.py": "import train.loop\n",
      "apps/cli.py": "import benchmarks.x\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n  import nothing\n",
  })
  bad = "\n".join(layer_violations(root))
  assert "mjx_damage.core (mjx_damage) imports tasks.thing (tasks)" in bad
  assert "tasks.thing (tasks) imports train.loop (train)" in bad
  assert "train.loop (train) imports apps.cli (apps)" in bad
  assert "backend mjx_damage.backends.a imports another backend, mjx_damage.backends.b" in bad
  assert "backend mjx_damage.backends.a imports the step layer (mjx_damage.physics)" in bad
  assert "apps.cli imports benchmarks.x" in bad
  assert "core module mjx_damage.health imports backend mjx_damage.backends.b" in bad
  assert ["train.loop", "train.other"] in import_cycles(root)
  clean = _tree(tmp_path / "clean", {"tasks/t.py": "import mjx_damage.core\n", "mjx_damage/core.py": ""})
  assert layer_violations(clean) == [] and import_cycles(clean) == []


# --- the core alone ---------------------------------------------------------------------

CORE_ALONE = r"""
import importlib.abc, sys

class Block(importlib.abc.MetaPathFinder):
  def find_spec(self, name, path, target=None):
    if name.split(".")[0] in ("tasks", "train", "apps"):
      raise ImportError(f"blocked for this test: {name}")
    return None

sys.meta_path.insert(0, Block())
import jax, mujoco
import mjx_damage as md
from mjx_damage import physics, render, plots, trajectory, overlay, video  # generic tools too
from mujoco import mjx

XML = '''<mujoco><option timestep="0.004"/><worldbody>
  <geom name="floor" type="plane" size="1 1 0.1"/>
  <body name="box" pos="0 0 0.3"><freejoint/><geom type="box" size="0.03 0.03 0.03" mass="0.2"/></body>
</worldbody></mujoco>'''
m = mujoco.MjModel.from_xml_string(XML)
b = md.bind(m, {"entities": {"box": {"params": "wineglass", "bodies": ["box"]}}})
sys_ = mjx.put_model(m)
step = jax.jit(lambda d, ds: physics.step(sys_, b, d, ds, 2))
d, ds = mjx.make_data(sys_), physics.init_state(b)
for _ in range(60):
  d, ds = step(d, ds)
h = float(ds.link_health.min())
assert 0.0 <= h < 100.0, h  # a 0.3 m drop of a wineglass-rated box does damage
assert not [k for k in sys.modules if k.split(".")[0] in ("tasks", "train", "apps")]
print("core alone ok, health", round(h, 2))
"""


def test_core_works_without_tasks_train_apps():
  env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""), JAX_PLATFORMS="cpu")
  r = subprocess.run([sys.executable, "-c", CORE_ALONE], cwd=ROOT, env=env, capture_output=True, text=True,
                     timeout=600)
  assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
  assert "core alone ok" in r.stdout
