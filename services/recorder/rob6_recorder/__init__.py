"""rob6 recorder service and session-log tools (MCAP)."""
