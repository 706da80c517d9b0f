"""The services' exception hierarchy: one root, ``ServiceError``, and a branch per kind of failure.

Every exception a rob6 service raises on purpose derives from ``ServiceError``, so a newcomer
can see at a glance what may go wrong and where it is defined::

    ServiceError                         rob6.errors
    ├── BusError                         rob6.bus.errors: a request that failed (code, message)
    │   └── BusTimeout                   a live instance did not answer in time
    ├── CallAbandoned                    rob6.bus.errors: the caller gave up on its request
    ├── StartupError                     rob6.service: cannot start; one line, no traceback
    ├── RefusedError                     declined on purpose; the message is the user's reason
    │   ├── ClaimRefused                 rob6.ownership: another owner holds the role
    │   ├── MotionRefused                rob6_planner.service: a motion refused before it started
    │   ├── Offline                      rob6_driver.motion: motion while the plant is unreachable
    │   ├── SignalError (ValueError)     rob6.vplus: a SIGNAL that cannot be carried out
    │   ├── GripperError                 rob6_gripper.sim: a command the gripper model refuses
    │   └── LiveRefused                  rob6_recorder.live: the live view may not run so
    ├── LinkError                        talking to a controller or device failed
    │   ├── RsiParseError (ValueError)   rob6_driver.links.rsi_codec: not a usable RSI packet
    │   ├── SimpleMessageError (ValueError)  rob6_driver.links.simple_message_codec: framing lost
    │   ├── IoPortError                  rob6_driver.links.adept_io: the I/O port did not switch
    │   └── SmpError                     rob6_gripper.smp: the Schunk module (SmpTimeout, ...)
    └── InputError                       what was given cannot be read
        ├── ParseError                   rob6_gateway.args: a malformed command argument
        └── NotMcap (ValueError)         rob6_recorder.reader: the file is not an MCAP recording

Where a class was a ``ValueError`` before it still is (its second base), so every ``except``
catches what it caught. Left outside on purpose: the gateway's ``ClientGone`` and ``Close``
(control flow of a connection, not failures) and the private retry signals of the bus and the
links (``_InstanceLost``, ``_Down``, ``_Lost`` under ``IoPortError``). The client library has
its own hierarchy for what a client sees (``rob6_client.Rob6Error``, clients/python/README.md);
the controller simulators in controllers/ stand apart from rob6 and keep theirs.
"""

from __future__ import annotations


class ServiceError(Exception):
    """Root of every exception a rob6 service raises on purpose (see the module docstring)."""


class RefusedError(ServiceError):
    """Something the service declines on purpose; the message is the reason, for the user."""


class LinkError(ServiceError):
    """Talking to a robot controller or a device failed; the message says why."""


class InputError(ServiceError):
    """Input that cannot be read: a command argument, a file."""
