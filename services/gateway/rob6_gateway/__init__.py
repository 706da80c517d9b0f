"""rob6 gateway service."""
