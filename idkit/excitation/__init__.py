"""Excitation trajectories: the plugin families, the optimiser that tunes them, and the checks that
make an optimised motion one a robot can run.

Modules (imported on demand, so loading a family imports neither the optimiser nor ``idkit.data``):

* ``paper``: eq. (39), the cylindrical robot's planned trajectory (plugin ``paper``).
* ``fourier``: a finite Fourier series per joint, Swevers et al. (plugin ``fourier``).
* ``criterion``: column-scaled condition number and D-optimality of the stacked base regressor, and
  the expected LS error under state and torque noise.
* ``feasible``: scaling any candidate motion into the robot's motion limits, and the largest common
  scale that passes any other test.
* ``effort``: the nominal model's torques, and acceleration limits derived from effort limits.
* ``collision``: self-collision with pinocchio + coal (optional), or why it was not checked.
* ``optimize``: ``optimize_excitation``, the batched search (particle swarm, then Adam).
* ``export``: a motion as samples at a controller rate (CSV/NPZ by joint name), and reading them.
* ``check``: ``python -m idkit.excitation.check <file> --robot <urdf>``: margins and violations.
* ``files``: an excitation as a YAML document (registry name + constructor options).
* ``spec``: an excitation from a family name, a file or an object (``scenario.excitation=``).
"""
