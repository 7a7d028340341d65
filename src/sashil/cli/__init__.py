# PYTHON_ARGCOMPLETE_OK
"""The ``sashil`` command: one verb per module in this package, loaded on use.

Each verb module defines ``HELP`` (one line), ``EXAMPLE`` (a command line), ``add_arguments(parser)``
and ``run(args) -> int``. Errors a user can cause end as one line on stderr and exit code 2 (bad
input) or the code of their :class:`~sashil.errors.SashilError` kind; never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import NoReturn

from sashil import __version__
from sashil.errors import (
    EXIT_STATUS_CODES,
    EXIT_STOPPED,
    ConfigError,
    DeadlineMissedError,
    SafetyTrip,
    SashilError,
    Stopped,
)

#: verb -> module (docs/architecture.md fixed verbs)
VERBS: dict[str, str] = {
    "drop-test": "sashil.cli.drop_test",
    "run": "sashil.cli.run",
    "sweep": "sashil.cli.sweep",
    "calibrate": "sashil.cli.calibrate",
    "identify": "sashil.cli.identify",
    "simulate": "sashil.cli.simulate",
    "emulate": "sashil.cli.emulate",
    "report": "sashil.cli.report",
    "laws": "sashil.cli.laws",
    "doctor": "sashil.cli.doctor",
    "replay": "sashil.cli.replay",
    "tune": "sashil.cli.tune",
    "compare": "sashil.cli.compare",
}

#: the exit codes explained in ``sashil --help`` (the codes themselves live in sashil.errors)
EXIT_CODES = {
    EXIT_STATUS_CODES["ok"]: "success",
    SashilError.exit_code: "the run failed (driver I/O error, unexpected error); the damper was set to 0 A first",
    ConfigError.exit_code: "bad input: a config key, parameter file, data file, CLI argument or port; nothing energised",
    SafetyTrip.exit_code: "a safety trip stopped the run (angle interlock, sensor timeout, stale samples)",
    DeadlineMissedError.exit_code: "a deadline was missed with overrun policy 'fail'",
    EXIT_STOPPED: "stopped by SIGINT/SIGTERM after a clean shutdown (0 A, data and summary written)",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2 (argparse's own convention)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    epilog = "exit codes:\n" + "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())
    parser = _Parser(
        prog="sashil",
        description="Hardware-in-the-loop control of the SAS rig with a rotary MR damper.",
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True, parser_class=_Parser)
    for verb, module_name in VERBS.items():
        module = importlib.import_module(module_name)
        verb_parser = sub.add_parser(
            verb,
            help=module.HELP,
            description=module.HELP,
            epilog=f"example:\n  {module.EXAMPLE}",
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(verb_parser)
        verb_parser.set_defaults(_module=module)
    return parser


@contextmanager
def _stop_outside_the_loop() -> Iterator[None]:
    """SIGTERM and SIGHUP outside the control loop (starting up, writing the results) end the verb
    like SIGINT does: :class:`~sashil.errors.Stopped`, one line, exit 130 — not a death by signal.
    Inside the loop, the loop's own handlers stop it cleanly at the next cycle (data and summary)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: object) -> None:
        raise Stopped(f"stopped by {signal.Signals(signum).name} before the loop ran or after it ended")

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    if argv is None:  # a shell asking for completions (argcomplete, when installed) is answered here
        from sashil.cli.completion import enable

        enable(parser)
    args = parser.parse_args(argv)
    from sashil.recording.run_folder import CREATED

    CREATED.clear()  # this invocation's folders only (main() may run many times in one process)
    try:
        with _stop_outside_the_loop():
            return int(args._module.run(args) or 0)
    except SashilError as err:
        if err.exit_code == ConfigError.exit_code:  # bad input: nothing written
            from sashil.recording.run_folder import discard_unused

            discard_unused()
        print(f"sashil {args.verb}: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print(f"sashil {args.verb}: interrupted", file=sys.stderr)
        return EXIT_STOPPED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
