"""rob6 kinematics service."""
