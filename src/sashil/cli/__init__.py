# PYTHON_ARGCOMPLETE_OK
"""The ``sashil`` command: one verb per module in this package, loaded on use.

:data:`VERBS` holds each verb's module and its one-line help, so ``sashil --help`` and
``sashil --version`` import no verb, and ``sashil VERB ...`` imports that verb's module only. A verb
module defines ``EXAMPLE`` (a command line), ``add_arguments(parser)`` (argparse only: no physics,
no numpy) and ``run(args) -> int``, which parses, calls the experiment's library function and prints. Errors a user can cause end as one line on stderr and exit code 2 (bad
input) or the code of their :class:`~sashil.errors.SashilError` kind; never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import NamedTuple, NoReturn

from sashil._version import __version__
from sashil.errors import (
    EXIT_STATUS_CODES,
    EXIT_STOPPED,
    ConfigError,
    DeadlineMissedError,
    LossError,
    SafetyTrip,
    SashilError,
    Stopped,
)


class Verb(NamedTuple):
    """A verb's module (imported on use) and its one line of help."""

    module: str
    help: str


#: verb -> its module and help (docs/architecture.md fixed verbs)
VERBS: dict[str, Verb] = {
    "drop-test": Verb(
        "sashil.cli.drop_test",
        "drop test: hold the arm at theta0, release, record the free oscillation at constant current(s)",
    ),
    "run": Verb(
        "sashil.cli.run",
        "run the rig in closed loop at a fixed rate (real clock), recording data.csv and timing",
    ),
    "sweep": Verb(
        "sashil.cli.sweep",
        "sweep: road excitation theta1 = A sin(phi(t)), a linear chirp or stepped sine (transmissibility table)",
    ),
    "calibrate": Verb(
        "sashil.cli.calibrate",
        "calibrate: run the drop-test/road plan on the rig, fit the damper model, validate it on held-out runs",
    ),
    "identify": Verb(
        "sashil.cli.identify",
        "identify the damper model from recorded runs and write a parameter file",
    ),
    "simulate": Verb(
        "sashil.cli.simulate",
        "simulate a model (from --params) on recorded inputs or a drop test, for validation",
    ),
    "emulate": Verb(
        "sashil.cli.emulate",
        "run the emulated rig (interface board + simulated plant) on a pty, for the serial or can driver",
    ),
    "report": Verb(
        "sashil.cli.report",
        "report on run folders: θ(t) overlays, hysteresis loops, transmissibility, timing, report.md",
    ),
    "laws": Verb(
        "sashil.cli.laws",
        "list the control laws found (built-in, installed packages, or a given class) and their parameters",
    ),
    "doctor": Verb(
        "sashil.cli.doctor",
        "check the machine, the port and the board for the rig: ok / warn / fail, what was found, the fix",
    ),
    "replay": Verb(
        "sashil.cli.replay",
        "run a law offline on a recorded run's samples: what it would have commanded, beside what was",
    ),
    "tune": Verb(
        "sashil.cli.tune",
        "change a running law's parameters (sashil run's tuning socket), or list them",
    ),
    "compare": Verb(
        "sashil.cli.compare",
        "run several laws on the same road and compare them (compare.md, metrics.csv, compare.png)",
    ),
    "panel": Verb(
        "sashil.cli.panel",
        "the bench in a browser: a run on a road, a drop test or a sweep, live traces, live tuning and STOP (127.0.0.1, token)",
    ),
}


#: the exit codes explained in ``sashil --help`` (the codes themselves live in sashil.errors)
EXIT_CODES = {
    EXIT_STATUS_CODES["ok"]: "success",
    SashilError.exit_code: "the run failed (driver I/O error, unexpected error); the damper was set to 0 A first",
    ConfigError.exit_code: "bad input: a config key, parameter file, data file, CLI argument or port; nothing energised",
    SafetyTrip.exit_code: "a safety trip stopped the run (angle interlock, sensor timeout, stale samples)",
    DeadlineMissedError.exit_code: "a deadline was missed with overrun policy 'fail'",
    LossError.exit_code: "the run lost more deadlines or samples than loop.max_missed_fraction / driver.max_lost_fraction allow (data kept)",
    EXIT_STOPPED: "stopped by SIGINT/SIGTERM after a clean shutdown (0 A, data and summary written)",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2 (argparse's own convention)
        self.exit(2, f"{self.prog}: error: {message}\n")


def add_verb(sub: argparse._SubParsersAction, verb: str) -> argparse.ArgumentParser:
    """The parser of ``verb``, its module imported and its arguments added."""
    entry = VERBS[verb]
    module = importlib.import_module(entry.module)
    verb_parser: argparse.ArgumentParser = sub.add_parser(
        verb,
        help=entry.help,
        description=entry.help,
        epilog=f"example:\n  {module.EXAMPLE}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    module.add_arguments(verb_parser)
    verb_parser.set_defaults(_module=module)
    return verb_parser


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``sashil`` parser. With ``argv``, only the verb it names is loaded (the others are listed
    by their help line, so ``sashil --help`` stays fast); without it, every verb is loaded (for
    documentation and shell completion)."""
    epilog = "exit codes:\n" + "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())
    parser = _Parser(
        prog="sashil",
        description="Hardware-in-the-loop control of the SAS rig with a rotary MR damper.",
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True, parser_class=_Parser)
    wanted = set(VERBS) if argv is None else {next((a for a in argv if not a.startswith("-")), "")}
    for verb, entry in VERBS.items():
        if verb in wanted:
            add_verb(sub, verb)
        else:  # listed in --help; never parsed (the verb in argv is the only one loaded)
            sub.add_parser(verb, help=entry.help)
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
    completing = argv is None and "_ARGCOMPLETE" in os.environ
    if argv is None:
        argv = sys.argv[1:]
    parser = build_parser(None if completing else argv)
    if completing:  # a shell asking for completions (argcomplete, when installed) is answered here
        from sashil.cli.completion import enable

        enable(parser)
    args = parser.parse_args(argv)
    from sashil.writer.run_folder import CREATED

    CREATED.clear()  # this invocation's folders only (main() may run many times in one process)
    try:
        with _stop_outside_the_loop():
            return int(args._module.run(args) or 0)
    except SashilError as err:
        if err.exit_code == ConfigError.exit_code:  # bad input: nothing written
            from sashil.writer.run_folder import discard_unused

            discard_unused()
        print(f"sashil {args.verb}: error: {err}", file=sys.stderr)
        return err.exit_code
    except KeyboardInterrupt:
        print(f"sashil {args.verb}: interrupted", file=sys.stderr)
        return EXIT_STOPPED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
