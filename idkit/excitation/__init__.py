"""Excitation trajectories: the plugin families and the optimiser that tunes them.

* ``paper`` (``PaperExcitation``): eq. (39), the cylindrical robot's planned trajectory.
* ``fourier`` (``FourierExcitation``): a finite Fourier series per joint (Swevers et al.).
* ``optimize_excitation``: coefficients minimising the column-scaled condition number (or
  maximising D-optimality) of the base regressor at the sample times, within the robot's limits.
* ``load_excitation`` / ``excitation_yaml``: an excitation as a YAML file (name + options).
"""

from idkit.excitation.criterion import CRITERIA, excitation_criterion, observation_matrix
from idkit.excitation.files import excitation_from_yaml, excitation_yaml, load_excitation
from idkit.excitation.fourier import FourierExcitation
from idkit.excitation.optimize import ExcitationResult, build_excitation, optimize_excitation
from idkit.excitation.paper import PaperExcitation

__all__ = [
    "CRITERIA",
    "ExcitationResult",
    "FourierExcitation",
    "PaperExcitation",
    "build_excitation",
    "excitation_criterion",
    "excitation_from_yaml",
    "excitation_yaml",
    "load_excitation",
    "observation_matrix",
    "optimize_excitation",
]
