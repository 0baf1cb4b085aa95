"""Physics chosen by the scene: materials, loads and their time functions, boundary conditions,
multi-field contact and ground motion. Nothing here runs unless a scene names it.

Importing this package registers every material and every effect shipped with pmpm
(pmpm.core.effects), in the order below: the order the solver calls their hooks in (Rayleigh
damping adds its viscous stress before an event scales a fading body's) and the order of the
energy columns. A new effect is one module and one line here.
"""
from pmpm.physics import materials  # noqa: F401  (registers the materials and plastic_work)
from pmpm.physics import boundary  # noqa: F401  (the effects, in hook order)
from pmpm.physics import loads  # noqa: F401
from pmpm.physics import groundmotion  # noqa: F401
from pmpm.physics import pushover  # noqa: F401
from pmpm.physics import damping  # noqa: F401
from pmpm.physics import rayleigh  # noqa: F401
from pmpm.physics import events  # noqa: F401
from pmpm.physics import supports  # noqa: F401
from pmpm.physics import fracture_nonlocal  # noqa: F401
from pmpm.physics import fracture_record  # noqa: F401
