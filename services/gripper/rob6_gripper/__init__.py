"""rob6 gripper service: the Adept's serial gripper, or its simulation, on the bus.

Library modules (the service wraps them):

* ``backend``     -- the interface (:class:`GripperBackend`, :class:`GripperStatus`,
                     :class:`Result`) and clocks
* ``sim``         -- physical simulation (:class:`GripperModel`, backend :class:`SimGripper`)
* ``smp``         -- Schunk Motion Protocol: frames, CRC, decoder, payloads (no I/O)
* ``schunk``      -- the serial client of a real module, backend :class:`SchunkGripper`
* ``fake_device`` -- a fake SMP module on a pseudo-terminal, for tests
"""
