"""Excitation trajectories: the plugin families and the optimiser that tunes them.

Modules (imported on demand, so loading a family imports neither the optimiser nor ``idkit.data``):

* ``paper``: eq. (39), the cylindrical robot's planned trajectory (plugin ``paper``).
* ``fourier``: a finite Fourier series per joint, Swevers et al. (plugin ``fourier``).
* ``criterion``: column-scaled condition number and D-optimality of the stacked base regressor.
* ``feasible``: scaling any candidate motion into the robot's motion limits.
* ``optimize``: ``optimize_excitation``, the batched search (particle swarm, then Adam).
* ``files``: an excitation as a YAML document (registry name + constructor options).
* ``spec``: an excitation from a family name, a file or an object (``scenario.excitation=``).
"""
