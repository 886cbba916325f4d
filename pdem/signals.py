"""Stop requests: SIGTERM, SIGINT or SIGUSR1 ask a run to stop at the next step boundary.

The handler only records the signal. Everything else (agreeing on the step over the ranks,
the checkpoint, closing the output) happens in ordinary code between steps, so a signal that
arrives while a file is being written interrupts nothing: a second signal is recorded and
ignored. Only the command line installs the handlers (:func:`install`); library code receives
a :class:`StopRequest` and merely polls it, so importing pdem changes no process state.
"""

from __future__ import annotations

import signal

SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)


class StopRequest:
    """``signum``: the first stop signal received (0: none). Polled once a step by the
    stepper and agreed over the ranks in the step's flag reduction."""

    def __init__(self):
        self.signum = 0

    def handler(self, signum, frame):
        # nothing but a store: async-signal-safe in the Python sense, and it never raises into
        # the code it interrupts (an HDF5 write, an MPI call)
        if not self.signum:
            self.signum = int(signum)

    def request(self, signum: int) -> None:
        """Ask for a stop without a signal (scripts, tests)."""
        self.handler(signum, None)


def install(stop: StopRequest | None = None) -> StopRequest:
    """Route the stop signals to ``stop`` (a new one by default); from the main thread."""
    stop = stop or StopRequest()
    for sig in SIGNALS:
        signal.signal(sig, stop.handler)
    return stop


def name(signum: int) -> str:
    """``SIGTERM`` for 15."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
