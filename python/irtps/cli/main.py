"""The ``irtps`` command: parse the arguments (`irtps.cli.parser`), run the command, and turn
its errors, warnings and interrupts into messages and exit statuses."""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import warnings

from irtps._shared.output_rule import escaped
from irtps._shared.resources import return_freed_memory
from irtps.cli.parser import build_parser
from irtps.errors import ArgumentError, IrtpsError, IrtpsWarning

__all__ = ["main"]


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every partial output is removed on the way out."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise _Terminated()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    if issubclass(category, IrtpsWarning):
        print(f"irtps: warning: {escaped(str(message))}", file=sys.stderr)
    else:
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def _stdout_closed() -> bool:
    """Whether what reads the standard output has closed it (``irtps ... | head``): polling it
    reports an error. Then it is pointed at the null device, so that nothing more is said at
    exit."""
    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    if not hasattr(select, "poll"):
        return False
    poller = select.poll()
    poller.register(descriptor, select.POLLOUT)
    if not any(events & select.POLLERR for _, events in poller.poll(0)):
        return False
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, descriptor)
    os.close(null)
    return True


def _argument_name(parser: argparse.ArgumentParser, command: str, argument: str) -> str:
    """An argument's name as `command` takes it on the command line: ``exclude_images`` is
    ``--exclude-images`` (an argument that is no option of the command keeps its name)."""
    flag = "--" + argument.replace("_", "-")
    subcommands = next(action for action in parser._actions if isinstance(action, argparse._SubParsersAction))
    return flag if flag in subcommands.choices[command]._option_string_actions else argument


def main(argv: list[str] | None = None) -> int:
    """Run the ``irtps`` command; returns the exit status.

    0 on success; 2 on bad input, printed as ``irtps: error: ...`` naming the file or
    field; 130 on Ctrl-C and 143 on SIGTERM, after removing any partial output; 141, as a
    command that SIGPIPE ends, with nothing said, when what reads its output has closed it
    (what was complete by then stays).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    return_freed_memory()
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default", IrtpsWarning)  # each message once
            warnings.showwarning = _show_warning
            args.run(args)
    except ArgumentError as err:
        print(
            f"irtps: error: {_argument_name(parser, args.command, err.argument)}: {escaped(err.problem)}",
            file=sys.stderr,
        )
        return 2
    except BrokenPipeError as err:
        if _stdout_closed():
            return 128 + signal.SIGPIPE
        print(f"irtps: error: {escaped(str(err))}", file=sys.stderr)
        return 2
    except (IrtpsError, OSError) as err:
        print(f"irtps: error: {escaped(str(err))}", file=sys.stderr)
        return 2
    except MemoryError as err:
        print(f"irtps: error: not enough memory ({escaped(str(err)) or 'allocation failed'})", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:
        print("irtps: interrupted; no partial output was left", file=sys.stderr)
        return 128 + signal.SIGTERM if isinstance(interrupt, _Terminated) else 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
