"""The rob6 bus: Zenoh sessions, key expressions, request/reply, liveliness, replicas.

Key expressions (``<id>`` is the robot id, so several robots share one network)::

    rob6/<id>/<service>/<instance>/<op>    queryable of one service instance (requests)
    rob6/<id>/alive/<service>/<instance>   liveliness token: the instance is up
    rob6/<id>/driver/state                 joint state, every driver cycle (at rest 10 Hz)
    rob6/<id>/gripper/state                gripper state
    rob6/<id>/control/<name>               verbosity, shutdown (gateway -> all)
    rob6/<id>/planner/config               the planner's settings (tool, base, speeds...)
    rob6/<id>/trace/<service>              the records below, in batches (recorder)

Records for the recorder (``Bus.trace``) leave in batches, one message per few
milliseconds (``TRACE_BATCH_S``): a JSON array of ``[suffix, record]`` pairs, read
with ``trace_records``. They come from a zenoh.ext advanced publisher that keeps the
last ``TRACE_CACHE_S`` of batches and numbers them: a recorder that was partitioned
away or restarted gets what it missed and learns of what it could not get
(``Bus.subscribe_traces``). The suffixes::

    trace/<service>/<op>                   each served request with its reply
    trace/gateway/session                  each client line in / reply out
    trace/gateway/event                    a client session opening or closing
    log/<service>                          a log record (rob6.logs.BusLogHandler)
    driver/state, gripper/state            each published state (``Bus.publish_state``)
    driver/link                            an event of the driver's robot link

Requests go to one *instance*: the bus watches the liveliness tokens and spreads the
calls of a replicated service (kinematics) over its live instances (least in flight,
then round robin). A robot has one driver, planner, gripper and gateway
(``OWNER_SERVICES``, claimed in ``rob6.ownership``): calls to those go to the one
instance this process follows (the first it saw alive), and subscriptions made with
``owner=`` drop samples any other instance publishes (every publication carries its
instance id as the Zenoh attachment), so a stray second driver is never mixed in.
Zenoh itself would send every query to one complete queryable, so replicas would sit
idle without this. When an instance vanishes mid-request (its token disappears) or
does not answer in time, a request to an idempotent service is retried once on
another instance; a hedged one (single-pose kinematics, ``Op.hedged``) not answered
after ``HEDGE_DELAY_S`` is sent a second time, to another live instance (or the same
one when it is the only one), and the first answer wins. A retry or a hedge prefers an
instance on another host (the host part of its id): its network path is not the first's.
Never for an owner service: one robot, one owner, a motion is never sent twice.
Everything else fails with a structured ``BusError``. A service with no live instance
is waited for (``LIVELINESS_GRACE_S``, within the call's deadline) before the call fails
``unavailable``: a token can be missing for a moment (an instance reconnecting). Only
then, or when the instance goes away mid-request: a live instance that does not answer
in time fails the call ``timeout`` (``BusTimeout``), naming what it waited for.

A reply that waits for the arm (``Op.waits``: a motion, a stop, the gripper) is not
bounded by the quick-call deadline: the handler announces how long and for what
(``Context.waiting``, an interim reply), and the caller's deadline becomes that plus
``rob6.deadlines.HOP_S``; a caller that is itself a handler passes the announcement on
(``request(..., waiting=ctx.waiting)``), so each hop outward waits a little longer.

A caller receives its reply on its own thread, from the query's Zenoh channel: no Python
callback and no hand-over between threads on the request path (``call._Exchange``). Zenoh
runs the other callbacks (liveliness, subscriptions, a hedge's second copy, the
queryables) on its own threads: they only hand data over and never block. Quick operations
are answered on Zenoh's thread; the others are taken from a FIFO queue by worker threads.

The bus is one package, a module per job; ``Bus`` (``core``) puts them together:

    session      the Zenoh session: configuration, opening, identity, key expressions
    codec        the wire format: JSON encoding, decoders by type, cids, the interim-reply mark
    errors       what a failed call raises (``BusError``, ``BusTimeout``, ``CallAbandoned``)
    liveliness   which instances are up, and which one a call goes to
    serve        a service's queryable, workers and answers (``Context``, ``Handler``)
    call         requests: deadline, retry, hedge, the reply on the calling thread
    pubsub       publish and subscribe, an owner's samples only
    trace        records for the recorder: batches out, the recorder's subscription in
    core         the ``Bus`` class

A constant is read where it is used: tune (or monkeypatch) it in its module, e.g.
``rob6.bus.call.LIVELINESS_GRACE_S`` or ``rob6.bus.trace.TRACE_REPAIR_S``.
"""

from .call import HEDGE_DELAY_S
from .codec import new_cid
from .core import Bus
from .errors import BusError, BusTimeout, CallAbandoned
from .pubsub import LIVE_TOPICS, decode
from .serve import Context, Handler
from .session import open_session, zenoh_config
from .trace import trace_records

__all__ = [
    "HEDGE_DELAY_S",
    "LIVE_TOPICS",
    "Bus",
    "BusError",
    "BusTimeout",
    "CallAbandoned",
    "Context",
    "Handler",
    "decode",
    "new_cid",
    "open_session",
    "trace_records",
    "zenoh_config",
]
