"""The end of a service's stop: its threads joined, and the ones Python cannot join left alone."""

from __future__ import annotations

import _thread
import signal
import threading

from rob6 import service


def test_a_native_threads_stand_in_is_not_joined() -> None:
    """A thread Python did not start (Zenoh's, foxglove's) that called into Python has a
    ``_DummyThread`` stand-in, which cannot be joined: the stop goes on without it."""
    seen, release = threading.Event(), threading.Event()

    def native() -> None:
        threading.current_thread()  # what any log call from such a thread does
        seen.set()
        release.wait(10)

    _thread.start_new_thread(native, ())
    assert seen.wait(5)
    handlers = {signum: signal.getsignal(signum) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        assert any(isinstance(t, threading._DummyThread) for t in threading.enumerate())
        worker = threading.Thread(target=release.wait, args=(0.2,))
        worker.start()
        service.end_threads(timeout=5.0)  # joins the worker, skips the stand-in, raises nothing
        assert not worker.is_alive()
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN  # from here on, a stop signal changes nothing
    finally:
        release.set()
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
