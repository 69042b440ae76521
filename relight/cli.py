"""``relight`` command line: parse arguments, build a config, call one library function.

Each subsystem adds its own subcommands through an ``add_commands(subparsers)``
function in the modules listed in :data:`COMMAND_MODULES`; a subcommand stores its
handler as ``func`` (taking the parsed args, returning an exit code).

Errors a user can cause (bad arguments, unreadable or inconsistent files) print one
line on stderr and exit 2; nothing is half-written.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

# Modules that contribute subcommands (each has add_commands(subparsers)).
COMMAND_MODULES = [
    "relight.commands.data",
    "relight.commands.demo",
    "relight.commands.probe",
    "relight.net.commands",
    "relight.verify.commands",
    "relight.inverse.commands",
    "relight.commands.blender",
]

EXIT_USAGE = 2


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
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # subsystem not installed in this build
                continue
            raise
        module.add_commands(sub)
    return parser


def user_errors() -> tuple[type, ...]:
    """Exception types that mean 'bad input' (one line, exit 2) rather than a bug."""
    from relight.backend import BackendError
    from relight.dataset import DatasetError
    from relight.fileio import OutputError
    from relight.render import ImageError
    from relight.scene.sampling import ConfigError
    from relight.scene.spec import SceneFileError
    errors = [BackendError, DatasetError, ImageError, ConfigError, SceneFileError, OutputError,
              FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError]
    for extra in ("relight.predictions:PredictionsError", "relight.net.io:ModelFileError",
                  "relight.probes:ProbeError", "relight.probe_geometry:ProbeError",
                  "relight.blender:BlenderError", "relight.engine:EngineError"):
        mod, _, cls = extra.partition(":")
        try:
            errors.append(getattr(importlib.import_module(mod), cls))
        except (ImportError, AttributeError):
            pass
    return tuple(errors)


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
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        sys.stderr.write("relight: interrupted (re-run the same command to resume)\n")
        return 130
    except user_errors() as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, OSError) and exc.filename:
            text = f"{exc.strerror}: {exc.filename}"
        sys.stderr.write(f"relight: error: {text}\n")
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
