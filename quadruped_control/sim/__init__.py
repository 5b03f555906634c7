"""Simulation: the plants (the paper's floating-base model and the tank model), servo models, the
closed-loop simulation that runs the robot's own controller, and the lock-step clock of the simulated
robot. Imports ``model``, ``control`` and ``analysis``."""
