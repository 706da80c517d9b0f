"""rob6 planner service: limits, configuration choice and Ruckig trajectories."""
