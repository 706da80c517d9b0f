"""rob6 gateway service: the rob6server text protocol on TCP, in front of the bus."""
