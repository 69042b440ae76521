"""``relight`` command line: parse arguments, build a config, call one library function.

Each subsystem adds its own subcommands through an ``add_commands(subparsers)``
function in the modules listed in :data:`COMMAND_MODULES`; a subcommand stores its
handler as ``func`` (taking the parsed args, returning an exit code).

Errors a user can cause (bad arguments, unreadable or inconsistent files) print one
line on stderr and exit 2; nothing is half-written.
"""
from __future__ import annotations

__all__ = [
    "COMMAND_MODULES", "EXIT_USAGE", "build_parser", "user_errors", "main",
]

import argparse
import importlib
import os
import sys

from relight.errors import user_errors   # the one list of bad-input errors (also for scripts)

# The command modules, in --help order; each has add_commands(subparsers). They sit on
# top of the library: a command parses arguments and calls one library function.
COMMAND_MODULES = [
    "relight.commands.data",       # generate, render
    "relight.commands.net",        # train, evaluate, predict
    "relight.commands.verify",     # compare, figure
    "relight.commands.inverse",    # invert, baseline
    "relight.commands.probe",      # probe
    "relight.commands.blender",    # export-blender
    "relight.commands.demo",       # demo
]

EXIT_USAGE = 2
# Options that name an output: errors while writing one name the option and the path given.
OUTPUT_OPTIONS = ("out", "trace", "qa")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse prints usage too; keep it short)
        sys.stderr.write(f"relight: error: {message}\n")
        sys.exit(EXIT_USAGE)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="relight",
                     description="Light direction and colour from one image (Sial et al.), "
                                 "verified with the Mitsuba 3 renderer.")
    from relight.commands.argtypes import threads
    parser.add_argument("--threads", type=threads, default=None,
                        help="Dr.Jit render threads (default: all cores)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name in COMMAND_MODULES:   # a module that fails to import is a broken install: let it raise
        importlib.import_module(name).add_commands(sub)
    return parser


def _quiet_libraries() -> None:
    """One line means one line: library warnings (torch, numpy, PIL) are not shown
    unless RELIGHT_WARNINGS=1."""
    if os.environ.get("RELIGHT_WARNINGS") != "1":
        import warnings
        warnings.simplefilter("ignore")
        os.environ.setdefault("PYTHONWARNINGS", "ignore")   # worker processes too


def main(argv: list[str] | None = None) -> int:
    _quiet_libraries()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.threads is not None:
        os.environ["RELIGHT_THREADS"] = str(args.threads)
    from relight import fileio
    fileio.name_outputs({f"--{name}": getattr(args, name, None) for name in OUTPUT_OPTIONS})
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        sys.stderr.write("relight: interrupted (re-run the same command to resume)\n")
        return 130
    except user_errors() as exc:
        return _one_line(exc)
    except OSError as exc:   # the file system refused an output outside the writers (a folder, a lock)
        path = exc.filename or next((getattr(args, n) for n in OUTPUT_OPTIONS if getattr(args, n, None)), ".")
        err = fileio.disk_error(exc, path) if exc.errno in fileio.DISK_ERRNOS else None
        if err is None:
            raise
        return _one_line(err)


def _one_line(exc: BaseException) -> int:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    if isinstance(exc, OSError) and exc.filename:
        from relight.fileio import describe_output
        text = f"{exc.strerror}: {describe_output(exc.filename)}"
    sys.stderr.write(f"relight: error: {text}\n")
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
