"""mjx_damage: damage-aware robot manipulation in MuJoCo MJX.

Pure damage evaluation models (mechanical, thermal, fluid) over batched MJX
state, health integrated at every physics substep, temperature and liquid
models MuJoCo lacks, and a Brax wrapper. See DAMAGE_MODEL.md for the model.
"""

from mjx_damage import compat as _compat

_compat.install()
_compat.import_mjx_quietly()

from mjx_damage.binding import Binding, bind, contact_forces, link_acceleration, link_velocity  # noqa: E402
from mjx_damage.config import resolve  # noqa: E402
from mjx_damage.env import DamageEnv  # noqa: E402
from mjx_damage.fluid import fluid_damage  # noqa: E402
from mjx_damage.health import MAX_HEALTH, entity_health  # noqa: E402
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
