"""The stop path's loop: send the rest frame until the board's readback confirms it, recovering the
link between tries, until a deadline.

The RT-DAC/USB2 keeps its last outputs when the host goes quiet, so a stop that meets a transfer
error must not give up at the first: it recovers the link (:meth:`BoardLink.recover
<sashil.drivers.rtdac_usb.BoardLink.recover>`: clear the endpoints' halt, else reset and reopen)
and sends the rest frame again. Free of I/O: the exchange, the check, the recovery and the clock
are the caller's callables, so the loop runs on a fake clock in tests.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, TypeVar

Readback = TypeVar("Readback")

#: how long to wait after a recovery that failed before the next try [s] (a board re-enumerating)
RETRY_PAUSE_S = 0.01


class RestOutcome(NamedTuple):
    """How the stop path's loop ended: the rest confirmed or not, the tries it took, the time it took
    [s], and the last error met (None: every try reached the board)."""

    confirmed: bool
    attempts: int
    elapsed_s: float
    last_error: BaseException | None


def rest_until_confirmed(
    send_rest_and_read: Callable[[], Readback],
    is_confirmed: Callable[[Readback], bool],
    recover: Callable[[], None],
    clock: Callable[[], float],
    deadline_s: float,
    sleep: Callable[[float], None] | None = None,
    pause_s: float = RETRY_PAUSE_S,
) -> RestOutcome:
    """Try ``send_rest_and_read`` until ``is_confirmed`` accepts its readback, or ``deadline_s`` has passed
    on ``clock`` [s] since the start (a try that begins before the deadline runs to its end).

    A try that raises (the exchange or the check) is followed by ``recover()`` while time is left; a
    recovery that raises too is the last error, and the loop pauses ``pause_s`` (through ``sleep``,
    when given) before the next try. A readback that is not yet at rest is tried again at once. Never
    raises an :class:`Exception`; returns a :class:`RestOutcome`."""
    start = clock()
    attempts = 0
    last_error: BaseException | None = None
    while True:
        attempts += 1
        try:
            if is_confirmed(send_rest_and_read()):
                return RestOutcome(True, attempts, clock() - start, last_error)
        except Exception as err:
            last_error = err
            if clock() - start >= deadline_s:
                break
            try:
                recover()
            except Exception as recover_err:
                last_error = recover_err
                if sleep is not None:
                    sleep(pause_s)
        if clock() - start >= deadline_s:
            break
    return RestOutcome(False, attempts, clock() - start, last_error)
