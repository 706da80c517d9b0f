"""kawasaki-as-sim: a Kawasaki FS03N controller running rob6's AS program pair (deploy/kawasaki).

It plays the PC program's side of the rob6-kas protocol on TCP (one client), executes the
point queue like the robot program (JMOVE with blending) on a simulated arm moving in real
time, refuses what the program and the controller refuse, and takes fault injections on a
JSON control channel. It shares no code with rob6.
"""
