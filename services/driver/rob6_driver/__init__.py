"""rob6 driver service: owns the robot (motion core, limit monitor, links to the plant)."""
