"""Command-line interface: ``myoexo <command> [options]``.

Each sub-command lives in the module that owns the concept and exposes two functions,
``add_arguments(parser)`` and ``run(args) -> int``; this file only routes to them, so the
modules stay independent and importing the CLI stays cheap.

A user's mistake (a bad value, a missing file or run folder, the shipped policy missing, a
folder in use by another run) is reported as one line, ``myoexo <command>: error:
<message>``, with exit status 2. A full disk (or quota) is one line too, with exit status 1:
what was written before stays intact, so the same command continues once space is freed.
A Ctrl-C that the command did not handle itself (a second one, during a graceful stop) is one
line with exit status 130. Any other exception is a bug and keeps its traceback.
``myoexo --debug <command>`` (or the environment variable ``MYOEXO_DEBUG=1``) shows the
traceback of all of these. Exit statuses of a run stopped by a signal: ``docs/long_runs.md``.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import textwrap
from collections.abc import Sequence
from importlib import metadata
from typing import Any, NoReturn

from myoexo.runtime.fields import FieldError, option_of
from myoexo.runtime.lifecycle import SIGNAL_EXIT_BASE

#: command -> (module implementing it, one-line help); a two-word command is a sub-command
#: of the group named by its first word (:data:`GROUPS`)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": (
        "myoexo.studies.demo",
        "the shipped controllers against the paper's PID on a few subjects (about 2 minutes)",
    ),
    "evaluate": ("myoexo.evaluation.cli", "run the paper's evaluation protocol"),
    "report": ("myoexo.evaluation.report", "write figures and the Markdown report of a run"),
    "results": (
        "myoexo.evaluation.results",
        "collect an evaluation into a result set; print its tables",
    ),
    "frontier": (
        "myoexo.studies.frontier",
        "torque vs settling per level: shaped PIDs, policies, the study's point, the frontier",
    ),
    "video": ("myoexo.viz.video", "render an episode of a controller to MP4 or GIF"),
    "twin export": ("myoexo.model.export", "write the human + exo twin as a standalone MJCF"),
    "twin calibrate": (
        "myoexo.studies.calibrate",
        "fit a reflex model (each model registers its own fit) so that the paper's PID "
        "behaves as in the study",
    ),
    "twin validate": (
        "myoexo.studies.validate",
        "hold every reflex model to the study's PID table and the clinical tests, side by side",
    ),
    "twin torque-readings": (
        "myoexo.studies.torque_readings",
        "compare four readings of the interaction torque with the study's numbers",
    ),
    "twin settling-bound": (
        "myoexo.studies.settling_bound",
        "the soonest an open-loop command settles each subject at the PID's final error, and "
        "at what interaction torque (an oracle on the selection subjects)",
    ),
    "twin hold-slope": (
        "myoexo.studies.hold_slope",
        "how much less torque holds the knee per degree it ends short, where the motor stalls "
        "(the slope the result sets' hold bounds read)",
    ),
    "twin tune-pid": ("myoexo.control.ziegler_nichols", "Ziegler-Nichols tuning on the twin"),
    "twin strap-lag": (
        "myoexo.studies.strap_lag",
        "fit the knee's lag behind the exo encoder per unit of command (the encoder guard's)",
    ),
    "twin fit-subject": (
        "myoexo.studies.fit_subject",
        "fit a personal twin (its reflex and passive knee) to one patient's clinical "
        "recordings with CMA-ES; the fit, its uncertainty and what the recordings cannot tell",
    ),
    "twin recovery": (
        "myoexo.studies.recovery",
        "fit-subject's own test: record and fit simulated people, compare each parameter "
        "and the controllers' outcome on the fitted twin with the truth",
    ),
    "clinic stretch": ("myoexo.clinical.stretch", "simulate the passive Tardieu stretch per level"),
    "clinic tardieu": ("myoexo.clinical.tardieu", "Tardieu test: catch angle R1, passive range R2"),
    "clinic pendulum": ("myoexo.clinical.pendulum", "Wartenberg pendulum test: relaxation index"),
    "clinic mas": ("myoexo.clinical.mas", "Modified Ashworth examination: resistance profile"),
    "clinic hold": (
        "myoexo.clinical.hold",
        "stretch and hold: does the resistance last after a fast stretch?",
    ),
    "clinic plot": ("myoexo.clinical.figures", "draw Fig. 2b and the stretch-test curves"),
    "clinic record": (
        "myoexo.clinical.recording",
        "a synthetic recording of a clinical test on the twin (CSV, the recording format)",
    ),
    "clinic check-recording": (
        "myoexo.clinical.check_recording",
        "read clinical recordings; one line per file, a bad file refused with what is wrong",
    ),
    "policy train": (
        "myoexo.training.cli",
        "train a learned controller (SAC, PPO or SBX's learners) on MyoExoKneeRandom-v0",
    ),
    "policy seeds": (
        "myoexo.training.seeds",
        "train several seeds of one configuration in parallel; aggregate them with 95 % CIs",
    ),
    "policy sweep": (
        "myoexo.studies.sweep.cli",
        "Ray Tune over training configurations, ranked on the acceptance criteria",
    ),
    "policy select": (
        "myoexo.training.select",
        "pick the checkpoint of a run that best meets the acceptance criteria",
    ),
    "policy gentleness": (
        "myoexo.studies.gentleness",
        "a gentleness-trained policy across its weights against the PID; the default weight",
    ),
    "policy export": ("myoexo.training.export", "export a trained policy (ONNX)"),
    "policy knee-estimator": (
        "myoexo.studies.knee_estimator",
        "give a student a fine-positioning layer: a knee estimator fitted on its own episodes",
    ),
    "policy distill": (
        "myoexo.studies.distill",
        "distil the full-state teacher into an exo-sensor student with memory (DAgger)",
    ),
}

#: group -> one-line help
GROUPS: dict[str, str] = {
    "twin": "the twin itself: export it, fit its reflex and PIDs, validate it",
    "clinic": "clinical examinations of the simulated patient",
    "policy": "train, select, distil and export learned controllers",
}

#: a command's earlier name -> its name now; the earlier name prints one line pointing to it
RENAMED: dict[str, str] = {
    "export-model": "twin export",
    "calibrate": "twin calibrate",
    "validate": "twin validate",
    "torque-readings": "twin torque-readings",
    "tune-pid": "twin tune-pid",
    "strap-lag": "twin strap-lag",
    "stretch-test": "clinic stretch",
    "tardieu": "clinic tardieu",
    "pendulum": "clinic pendulum",
    "mas-exam": "clinic mas",
    "stretch-hold": "clinic hold",
    "plot-spasticity": "clinic plot",
    "train": "policy train",
    "seeds": "policy seeds",
    "sweep": "policy sweep",
    "select": "policy select",
    "export-policy": "policy export",
    "distill": "policy distill",
}

#: Exceptions that report a user's mistake rather than a bug (plus the project's
#: ``PolicyUnavailableError``, see :func:`is_user_error`).
USER_ERRORS: tuple[type[BaseException], ...] = (
    ValueError,
    FileNotFoundError,
    FileExistsError,
    NotADirectoryError,
    IsADirectoryError,
    PermissionError,
)


#: ``errno`` values of a write that found no space left (disk full, quota exceeded).
NO_SPACE_ERRNOS: frozenset[int] = frozenset({errno.ENOSPC, errno.EDQUOT})

#: Exit status of a command stopped by a full disk.
EXIT_NO_SPACE = 1

#: Exit status of a user error.
EXIT_USER_ERROR = 2


class HelpFormatter(argparse.HelpFormatter):
    """argparse's help layout, except that a word longer than the line (a URL) is never
    broken, nor a word at its hyphens: a URL in a help text stays one piece to copy."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.wrap(
            " ".join(text.split()), width, break_long_words=False, break_on_hyphens=False
        )

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return textwrap.fill(
            " ".join(text.split()),
            width,
            initial_indent=indent,
            subsequent_indent=indent,
            break_long_words=False,
            break_on_hyphens=False,
        )


class ArgumentParser(argparse.ArgumentParser):
    """The parser of ``myoexo`` and of every sub-command (their own sub-parsers included):
    :class:`HelpFormatter` by default, and a mistake on the command line reported as one
    line, ``<prog>: error: <message>``, with exit status 2."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(
            EXIT_USER_ERROR,
            f"{self.prog}: error: {_one_line(message)} (see '{self.prog} --help')\n",
        )


def version() -> str:
    """The installed distribution's version (the package's own ``__version__`` when the
    package runs from a source tree that was never installed)."""
    try:
        return metadata.version("myoexo")
    except metadata.PackageNotFoundError:
        from myoexo import __version__

        return __version__


class PluginAction(argparse.Action):
    """``--plugin MODULE``: import the module while the command line is read (before the
    sub-command's options, so ``--reflex NAME`` finds what it registers) and add it to
    ``MYOEXO_PLUGINS``, which worker processes inherit."""

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: Any = None):
        from myoexo.spasticity.registry import PLUGINS_ENV, load_plugins

        try:
            load_plugins(str(values))
        except ImportError as exc:
            parser.error(str(exc))
        names = [m for m in os.environ.get(PLUGINS_ENV, "").split(",") if m]
        os.environ[PLUGINS_ENV] = ",".join(dict.fromkeys([*names, str(values)]))
        setattr(namespace, self.dest, [*(getattr(namespace, self.dest, None) or []), values])


def build_parser() -> argparse.ArgumentParser:
    """Parser with one sub-parser per command (an import error of a command surfaces)."""
    parser = ArgumentParser(
        prog="myoexo",
        description="myoexo: knee-exoskeleton digital twin with spastic reflexes on MyoSuite.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the full traceback of errors (also: MYOEXO_DEBUG=1)",
    )
    parser.add_argument(
        "--plugin",
        action=PluginAction,
        metavar="MODULE",
        help="import MODULE first (repeatable): a module that registers reflex models "
        "(myoexo.spasticity.register_reflex); worker processes import it too "
        "(also: MYOEXO_PLUGINS=mod1,mod2)",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    groups: dict[str, Any] = {}
    for name, (module_name, help_text) in COMMANDS.items():
        group, _, leaf = name.rpartition(" ")
        if group and group not in groups:
            g = sub.add_parser(group, help=GROUPS[group], description=GROUPS[group])
            groups[group] = g.add_subparsers(dest="subcommand", required=True, metavar="COMMAND")
        module = importlib.import_module(module_name)
        # argparse %-formats a sub-command's help (for %(prog)s and the like): a literal
        # "%" of the one-line help is doubled, the description is printed as written
        p = (groups[group] if group else sub).add_parser(
            leaf, help=help_text.replace("%", "%%"), description=help_text
        )
        module.add_arguments(p)
        p.set_defaults(_module=module, _command=name, _parser=p)
    return parser


def renamed_command(argv: Sequence[str]) -> str | None:
    """The earlier command name that ``argv`` calls, if any (:data:`RENAMED`)."""
    words = iter(argv)
    for word in words:
        if word == "--plugin":
            next(words, None)
        elif not word.startswith("-"):
            return word if word in RENAMED else None
    return None


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` reports a user's mistake (one line, exit 2) rather than a bug."""
    if isinstance(exc, USER_ERRORS):
        return True
    from myoexo.control.specs import PolicyUnavailableError

    return isinstance(exc, PolicyUnavailableError)


def _one_line(message: str) -> str:
    return " ".join(line.strip() for line in message.splitlines() if line.strip())


def _fail(command: str, message: str, status: int = EXIT_USER_ERROR) -> int:
    print(f"myoexo {command}: error: {_one_line(message)}", file=sys.stderr)
    return status


def _message(exc: BaseException, parser: argparse.ArgumentParser) -> str:
    """The message of a user error; a config field's error names the command's option for
    that field when it has one (``--subjects = -1 ...``, not ``ValidationConfig.subjects``)."""
    if isinstance(exc, FieldError):
        flag = option_of(parser, exc.field)
        if flag is not None:
            return exc.describe(flag)
    return str(exc) or type(exc).__name__


def is_no_space_error(exc: BaseException) -> bool:
    """Whether ``exc`` is a write that found the disk (or the quota) full."""
    return isinstance(exc, OSError) and exc.errno in NO_SPACE_ERRNOS


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``myoexo`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    old = renamed_command(argv)
    if old is not None:
        return _fail(old, f"this command is now 'myoexo {RENAMED[old]}'")
    args, extra = build_parser().parse_known_args(argv)
    if extra:
        args._parser.error(f"unrecognized arguments: {' '.join(extra)}")
    command = args._command
    debug = args.debug or os.environ.get("MYOEXO_DEBUG", "") not in ("", "0")
    try:
        return int(args._module.run(args) or 0)
    except SystemExit as exc:
        # a command that stops with a message (``SystemExit("<command>: ...")``)
        if debug or not isinstance(exc.code, str):
            raise
        message = exc.code.removeprefix(f"{command}: ")
        return _fail(command, message)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"myoexo {command}: interrupted", file=sys.stderr)
        return SIGNAL_EXIT_BASE + int(signal.SIGINT)
    except Exception as exc:
        if not debug and isinstance(exc, OSError) and is_no_space_error(exc):
            where = f" while writing {exc.filename}" if exc.filename else ""
            return _fail(
                command,
                f"{exc.strerror or 'no space left on device'}{where}; what was written "
                "before is intact: free some space and run the same command again",
                EXIT_NO_SPACE,
            )
        if debug or not is_user_error(exc):
            raise
        return _fail(command, _message(exc, args._parser))


if __name__ == "__main__":
    sys.exit(main())
