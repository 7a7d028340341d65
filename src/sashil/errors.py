"""The sashil exception tree: one root, a few kinds (after python-can's ``CanError`` tree).

Every error a user can cause (a config key, a data file, a CLI argument, a wire frame) is one of
these, carries a one-line message naming *what* and *where*, and is turned into an exit code by the
CLI. Foreign exceptions (``serial.SerialException``, ``can.CanError``, ``OSError``) are wrapped at the
driver boundary with ``raise DriverIOError(...) from err``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


class SashilError(Exception):
    """Root of every error sashil raises on purpose."""

    #: process exit code the CLI uses for this kind of error
    exit_code: int = 1


class ConfigError(SashilError, ValueError):
    """A config file, parameter file or CLI argument is wrong (names the file/key and what was expected)."""

    exit_code = 2


class DataFileError(SashilError, ValueError):
    """A recorded data file cannot be used (missing column, NaN, time not increasing, ...)."""

    exit_code = 2


class DriverError(SashilError):
    """A rig driver failed: the backend is unknown, unavailable, or could not be opened."""

    exit_code = 2


class DriverIOError(DriverError):
    """Reading from or writing to the rig failed during a run."""

    exit_code = 1


class DriverTimeoutError(DriverIOError, TimeoutError):
    """The rig did not answer in time."""


class ProtocolError(DriverIOError):
    """A frame from the device is malformed, or the device speaks another protocol version."""


class LawError(SashilError):
    """The control law raised, or returned NaN, an infinity or a non-number: the loop stops at 0 A."""

    exit_code = 1


class RecordingError(SashilError):
    """Writing the run's data failed mid-run (a full or read-only disk): the loop stops at 0 A."""

    exit_code = 1


class DiskSpaceError(SashilError):
    """The disk of the run folder cannot hold the run's data: refused before anything is energised."""

    exit_code = 2


class SafetyTrip(SashilError):
    """The safety supervisor stopped the run (angle interlock, sensor timeout, stale samples...)."""

    exit_code = 3


class DeadlineMissedError(SashilError):
    """The loop missed a deadline and its overrun policy is ``fail``."""

    exit_code = 4


class LossError(SashilError):
    """A run lost more of its deadlines or samples than the config allows (``loop.max_missed_fraction``,
    ``driver.max_lost_fraction``): its data are kept, but it does not end ``ok``."""

    exit_code = 5


#: the exit code of a clean stop on SIGINT/SIGTERM/SIGHUP (128 + SIGINT, the shell's convention)
EXIT_STOPPED = 130


class Stopped(SashilError):
    """A signal stopped the run after a clean shutdown (0 A, road at rest; the data up to it kept)."""

    exit_code = EXIT_STOPPED


#: summary.json ``exit_status`` -> process exit code ("error": 1 unless the error carries its own)
EXIT_STATUS_CODES: dict[str, int] = {
    "ok": 0,
    "stopped": EXIT_STOPPED,
    "safety_trip": SafetyTrip.exit_code,
    "deadline_missed": DeadlineMissedError.exit_code,
    "lossy": LossError.exit_code,
    "error": SashilError.exit_code,
}


def status_of(error: BaseException) -> str:
    """summary.json ``exit_status`` of a run that ended with ``error``."""
    if isinstance(error, (Stopped, KeyboardInterrupt)):
        return "stopped"
    if isinstance(error, SafetyTrip):
        return "safety_trip"
    if isinstance(error, DeadlineMissedError):
        return "deadline_missed"
    if isinstance(error, LossError):
        return "lossy"
    return "error"


def exit_code_of(status: str, error: BaseException | None = None) -> int:
    """The process exit code of a run that ended with ``status`` (and ``error``, if any)."""
    if status == "error" and isinstance(error, SashilError):
        return error.exit_code
    return EXIT_STATUS_CODES.get(status, SashilError.exit_code)


def error_fields(err: BaseException) -> dict[str, Any]:
    """An error as it crosses to another process (a loop process's report): its class name, its
    line and its exit code (:func:`error_of` reads it back)."""
    return {"type": type(err).__name__, "text": str(err) or type(err).__name__, "exit_code": exit_code_of("error", err)}


def error_of(fields: Mapping[str, Any]) -> BaseException:
    """The error another process reported (:func:`error_fields`), as its sashil class when it has one."""
    cls = globals().get(str(fields.get("type")))
    text = str(fields.get("text"))
    if isinstance(cls, type) and issubclass(cls, SashilError):
        return cls(text)
    err = SashilError(f"{fields.get('type')}: {text}")
    err.exit_code = int(fields.get("exit_code") or 1)
    return err
