"""Analysis of attitude trajectories, simulated or recorded: the paper's metrics, figures and the bag
report. Independent of the controller (imports ``quadruped_common`` only, and itself)."""
