"""Applications: the top layer. The ``mjx-damage`` command line (:mod:`apps.cli`), the name
resolvers (``--task place_plate``, ``--policy scripted:safe|checkpoint:RUN|random|zero``,
:mod:`apps.resolve`), and the tools built on them: evaluation and sweep CLIs, the render
CLI, the throughput harness (:mod:`apps.bench`), the demo.

Imports flow one way (``tests/test_layering.py``): ``mjx_damage`` ← ``tasks`` ←
``train`` ← ``apps``. Nothing below imports this package.
"""
