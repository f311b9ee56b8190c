"""The ``exubio`` command: parse, call, print. Exit codes: 0 ok (verdicts ok or check), 1 a
reconstruction failed or a verdict is fail (with --method both: one method failed and the other's
result is written), 2 bad input (also an output folder that cannot be written or fills up), 130
interrupted (Ctrl-C). Results go to files, logs to stderr.

One module per command (``exubio/cli/<command>.py``: its options and its body, a few calls into the
run layer), what they share in ``exubio/cli/common.py``; this module assembles the parser and turns
exubio's errors into one line and an exit code. A command module imports its work only when it runs,
so ``exubio --help`` stays fast.
"""
from __future__ import annotations

import signal
import sys


def _interrupted_while_starting(signum, frame) -> None:  # noqa: ARG001
    """Ctrl-C while this module's own imports run (before main() can catch it): one line, exit 130."""
    sys.stderr.write("exubio: interrupted; nothing was written\n")
    raise SystemExit(130)


if sys.argv[:1] == ["-m"] and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import argparse  # noqa: E402
import logging  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Sequence  # noqa: E402

import exubio  # noqa: E402
from exubio.cli import calibrate, demo, export_model, live, protocols, reconstruct, simulate, study, validate, view  # noqa: E402
from exubio.cli.common import EXIT_BAD_INPUT, EXIT_CODES_HELP, EXIT_FAILED, EXIT_INTERRUPTED  # noqa: E402
from exubio.cli.demo import EXAMPLE_COMMAND  # noqa: E402,F401 - the demo's own command, named by the tests
from exubio.errors import ExubioError, InputError, ModelError, ProtocolError, ReconstructionError  # noqa: E402
from exubio.run import interrupt  # noqa: E402 - Ctrl-C noted (small: no pipeline)
from exubio.truth.locator_cli import add_parser as add_locator_parser  # noqa: E402 - small: its work is imported when it runs

COMMANDS = (simulate, reconstruct, calibrate, validate, export_model, study, view, protocols, live)
"""The command modules, in the order of exubio --help; each has add_parser(sub, common)."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="exubio", epilog=EXIT_CODES_HELP, description="Upper-extremity joint kinematics from skin markers "
                                "(potential-field and least-squares methods on Exudyn).")
    p.add_argument("--version", action="version", version=f"exubio {exubio.__version__}")
    # -v/-q work before and after the subcommand (SUPPRESS: a subcommand's default does not reset them)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="log details to stderr")
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="no progress bars, shorter output")
    p.add_argument("-v", "--verbose", action="store_true", help="log details to stderr")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, shorter output")
    sub = p.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub, common)
    add_locator_parser(sub, common)  # exubio locator: exubio/truth/locator_cli.py
    from exubio.synth.sta_fit_cli import add_parser as _add_sta_fit
    _add_sta_fit(sub, common)
    demo.add_parser(sub, common)
    from exubio.truth.cli_truth import add_parser as add_truth_parser
    add_truth_parser(sub, common)
    from exubio.truth.uncertainty_fit_cli import add_parser as add_uncertainty_fit_parser
    add_uncertainty_fit_parser(sub, common)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns its exit code. An output folder the command created and left empty
    (it failed before writing anything) is removed: a failed run leaves nothing behind."""
    new_folder: list[Path] = []
    try:
        return _main(argv, new_folder)
    finally:
        for folder in new_folder:
            try:
                if folder.is_dir() and not any(folder.iterdir()):
                    folder.rmdir()
            except OSError:
                pass


def _main(argv: Sequence[str] | None, new_folder: list[Path]) -> int:
    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)  # from here KeyboardInterrupt, caught below
    with interrupt.noted():
        try:  # Ctrl-C at any moment, also while the command's modules are still being imported: exit 130
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                                format="%(levelname)s %(name)s: %(message)s")
            out = getattr(args, "out", None)
            if isinstance(out, str) and out:  # the folders the run may create, deepest first
                new_folder += [f for f in (Path(out), *Path(out).parents) if not f.exists()]
            return int(args.func(args))
        except BaseException as exc:  # noqa: BLE001 - Ctrl-C as whatever Exudyn made of it (run.interrupt)
            if not (isinstance(exc, KeyboardInterrupt) or interrupt.pressed() and not isinstance(exc, SystemExit)):
                return _failed(exc)
        newline = "\n" if sys.stderr.isatty() else ""  # a progress bar's line is left open
        print(f"{newline}exubio: interrupted; results that were not complete were not written (the same command "
              "again resumes: it keeps what is complete)", file=sys.stderr)
        return EXIT_INTERRUPTED


def _failed(exc: BaseException) -> int:
    """The exit code of an error of exubio's (said on one line); any other error goes on."""
    if isinstance(exc, (InputError, ProtocolError, ModelError)):
        print(f"exubio: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if isinstance(exc, ReconstructionError):
        print(f"exubio: reconstruction failed: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if isinstance(exc, ExubioError):
        print(f"exubio: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    raise exc


def run() -> None:
    """The ``exubio`` command (console script and ``python -m exubio.cli``): main(), then exit with its
    code. Once main() has returned the work is done and written; a Ctrl-C during the interpreter's
    teardown (it restores the default handler there, which would kill the process with -SIGINT, no
    message, though every result is complete) is then ignored."""
    code = main()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _forget_a_handled_interrupt()
    sys.exit(code)


def _forget_a_handled_interrupt() -> None:
    """A Ctrl-C that lands while an ``exec`` of a string runs (SciPy's imports run some) sets CPython's
    "unhandled KeyboardInterrupt" flag, though main() caught it and returns 130; ``python -m exubio.cli``
    then ends by SIGINT (exit -2) instead of 130. Every ``exec`` of a string starts by clearing that
    flag (CPython's run_eval_code_obj), so one more, of nothing, clears it."""
    exec("pass")  # noqa: S102 - a constant: see above


if __name__ == "__main__":
    run()
