"""Analysis of a compiled system: static equilibrium, linearisation, modes and stability, the
Jacobian of a body point, inverse dynamics.  Each function takes the ``System`` first; the
``System`` methods of the same names call them."""
from mbcomp.analysis.equilibrium import equilibrium, reduced_forces
from mbcomp.analysis.equilibrium import changing_inputs, rest_states
from mbcomp.analysis.inverse import GeneralisedForces, inverse_dynamics
from mbcomp.analysis.jacobian import jacobian
from mbcomp.analysis.linear import Linearization, linearize
from mbcomp.analysis.modes import Modes, modes

__all__ = ["equilibrium", "reduced_forces", "rest_states", "changing_inputs", "linearize", "Linearization",
           "modes", "Modes", "jacobian",
           "inverse_dynamics", "GeneralisedForces"]
