"""kawasaki-as-sim: a Kawasaki FS03N controller executing an AS program (rob6's deploy/kawasaki/rob6.as).

It loads the AS file as the controller would (a step it cannot read is refused), runs its
PC programs and its robot program with an interpreter of the AS subset rob6.as uses, gives
them the controller's TCP/IP option on real sockets, its switches and a simulated arm that
moves in real time when the robot program's JMOVEs say so, and takes fault injections on a
JSON control channel. It shares no code with rob6.
"""
