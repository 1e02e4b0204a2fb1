"""mjx_damage: damage-aware robot manipulation in MuJoCo MJX.

Pure damage evaluation models (mechanical, thermal, fluid) over batched MJX
state, health integrated at every physics substep, temperature and liquid
models MuJoCo lacks, and a Brax wrapper. See docs/DAMAGE_MODEL.md for the model.

Importing the package sets two process-wide JAX options before any backend
starts (see :mod:`mjx_damage.runtime`): two XLA:CPU flags (the scheduler flag that
avoids a thread-pool deadlock of batched MJX calls on CPU, and the older fusion
emitters, without which deep kinematic chains such as the Panda's run 100× slower;
added only for jaxlib < 0.11, which no longer knows it),
and JAX's persistent
compilation cache in the user's cache directory.
"""

from mjx_damage import runtime as _runtime

_runtime.configure_xla_cpu()

from mjx_damage import compat as _compat  # noqa: E402

_compat.install()
_compat.import_mjx_quietly()
_runtime.enable_compilation_cache()

from mjx_damage.backends.mjx_jax import contact_forces  # noqa: E402
from mjx_damage.binding import Binding, bind  # noqa: E402
from mjx_damage.config import resolve  # noqa: E402
from mjx_damage.env import DamageEnv  # noqa: E402
from mjx_damage.fluid import fluid_damage  # noqa: E402
from mjx_damage.health import MAX_HEALTH, entity_health  # noqa: E402
from mjx_damage.kinematics import link_acceleration, link_velocity  # noqa: E402
from mjx_damage.mechanical import mechanical_damage, mechanical_load  # noqa: E402
from mjx_damage.params import (  # noqa: E402
    DEFAULT_TAU,
    DamageParams,
    ObjectParams,
    known_objects,
    object_params,
)
from mjx_damage.physics import DamageState, init_state, step, step_without_damage, substep  # noqa: E402
from mjx_damage.signals import Damage, LinkSignals, evaluate  # noqa: E402
from mjx_damage.thermal import thermal_damage  # noqa: E402
from mjx_damage.wrapper import DamageWrapper  # noqa: E402

__all__ = [
    "Binding", "bind", "contact_forces", "link_acceleration", "link_velocity", "resolve",
    "DamageEnv", "fluid_damage", "MAX_HEALTH", "entity_health", "mechanical_damage",
    "mechanical_load", "DEFAULT_TAU", "DamageParams", "ObjectParams", "known_objects",
    "object_params", "DamageState", "init_state", "step", "step_without_damage", "substep",
    "Damage", "LinkSignals", "evaluate", "thermal_damage", "DamageWrapper",
]
