"""rob6 planner service."""
