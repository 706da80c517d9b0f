"""rob6 driver service."""
