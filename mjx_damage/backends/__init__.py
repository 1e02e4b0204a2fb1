"""Physics backends: one module per simulator, each turning that simulator's state into link signals.

A backend reads its simulator's contact layout and kinematics and returns the
quantities of :class:`mjx_damage.signals.LinkSignals` (world-frame contact
forces on tracked links, link accelerations and velocities). Everything after
that (damage rates, health, temperature, liquid) is backend-independent core.

* :mod:`mjx_damage.backends.mjx_jax`: MuJoCo MJX, JAX implementation (jittable);
* :mod:`mjx_damage.backends.mjx_warp`: MuJoCo MJX, Warp implementation (a batch at a time: one contact
  list for every world);
* :mod:`mjx_damage.backends.native`: native MuJoCo ``MjData`` (numpy).

The steps that drive a simulator and apply the damage are core:
:mod:`mjx_damage.physics` (MJX), :mod:`mjx_damage.warp_step` (MJX on Warp) and
:mod:`mjx_damage.native` (MuJoCo).

Backends import the core's data types (``Binding``, ``LinkSignals``), never
each other, never the step layer (``physics``, ``env``, ``wrapper``) and never
``tasks``/``train``/``apps`` (``tests/test_layering.py``). This package
imports no backend itself, so importing one does not load the others.
"""
