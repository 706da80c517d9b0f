"""rob6 shared library: bus, messages, robot models, configuration."""
