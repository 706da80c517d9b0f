"""One method per protocol command, generated from ``protocol.COMMANDS``.

``RobotCommands`` (blocking) and ``AsyncRobotCommands`` (coroutines) differ only in
``await``; both hand the encoded line and the command to ``self._call``, which the
I/O classes provide. Type checkers and IDEs read ``_methods.pyi``, generated from the
same table: ``python -m rob6_client._stubgen`` rewrites it (a test checks it is current).
"""

from __future__ import annotations

import inspect

from .protocol import COMMANDS, ENCODERS, Command, docstring

_SELF = inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)
_TIMEOUT = inspect.Parameter("timeout", inspect.Parameter.KEYWORD_ONLY, default=None,
                             annotation="float | None")


def _signature(command: Command) -> inspect.Signature:
    params = [inspect.Parameter(p.name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=p.default,
                                annotation=ENCODERS[p.kind][1]) for p in command.params]
    return inspect.Signature(params)


def _finish(method, command: Command, signature: inspect.Signature):
    method.__name__ = method.__qualname__ = command.method
    method.__doc__ = docstring(command)
    method.__signature__ = signature.replace(
        parameters=[_SELF, *signature.parameters.values(), _TIMEOUT],
        return_annotation=command.reply.returns)
    return method


def _sync(command: Command):
    signature = _signature(command)

    def method(self, *args, timeout: float | None = None, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        return self._call(command, command.encode(bound.args), timeout)
    return _finish(method, command, signature)


def _async(command: Command):
    signature = _signature(command)

    async def method(self, *args, timeout: float | None = None, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        return await self._call(command, command.encode(bound.args), timeout)
    return _finish(method, command, signature)


class RobotCommands:
    """Every rob6server command as a blocking method (see protocol.COMMANDS)."""


class AsyncRobotCommands:
    """Every rob6server command as a coroutine method (see protocol.COMMANDS)."""


for _command in COMMANDS.values():
    setattr(RobotCommands, _command.method, _sync(_command))
    setattr(AsyncRobotCommands, _command.method, _async(_command))
