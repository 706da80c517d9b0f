"""adept-sm-sim: an Adept Viper s850 controller running the ROS-Industrial V+ server.

It plays the controller's side of simple_message on TCP (motion port 11000, state
port 11002, optionally the I/O port 11001) with a simulated arm moving in real time,
and takes fault injections on a JSON control channel. It shares no code with rob6.
"""
