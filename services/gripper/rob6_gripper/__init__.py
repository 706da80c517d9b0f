"""rob6 gripper service."""
