"""The command line's parser and output checks: every error in one line.

argparse prints its usage (several lines) above an error; :class:`OneLineParser` prints
one line instead, pointing at ``--help``, and a near miss of a command or a choice gets
a suggestion (``phantomtouch serv`` → did you mean 'serve'?). :func:`check_output_file`
refuses an output file that cannot be written, naming why, before any work is done.
"""

from __future__ import annotations

import argparse
import difflib
import re
from pathlib import Path
from typing import NoReturn

from phantomtouch.errors import ParameterError

_INVALID_CHOICE = re.compile(
    r"argument (?P<argument>[^:]+): invalid choice: '?(?P<value>.*?)'? "
    r"\(choose from (?P<choices>.*)\)"
)


def _choices(listed: str) -> list[str]:
    return [choice.strip().strip("'\"") for choice in listed.split(",")]


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr, exit status 2.

    Runs on the main thread, while the command line is parsed.
    """

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: MESSAGE`` (with a suggestion for a near miss) and exit 2."""
        invalid = _INVALID_CHOICE.search(message)
        hint = f"{self.prog} --help lists"
        if invalid is None:
            self.exit(2, f"{self.prog}: {message} ({hint} the options)\n")
        value, choices = invalid["value"], _choices(invalid["choices"])
        near = difflib.get_close_matches(value, choices, n=1, cutoff=0.5)
        suggestion = f"; did you mean {near[0]!r}?" if near else ""
        if self._subparsers is not None and any(
            isinstance(action, argparse._SubParsersAction) and action.dest == invalid["argument"]
            for action in self._subparsers._group_actions
        ):
            self.exit(2, f"{self.prog}: no command {value!r}{suggestion} ({hint} the commands)\n")
        self.exit(2, f"{self.prog}: {message}{suggestion}\n")


def check_output_file(path: str | Path, option: str) -> None:
    """Refuse an output file that cannot be written, naming the reason.

    Creates (or empties) the file, as writing it would. Runs on the main thread.

    Raises
    ------
    ParameterError
        The folder is missing, the path is a folder, or the system refuses the file.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise ParameterError(
            f"{option} {str(path)!r}: the folder {str(path.parent)!r} does not exist"
        )
    if path.is_dir():
        raise ParameterError(f"{option} {str(path)!r} is a folder; give a file name in it")
    try:
        path.open("wb").close()
    except OSError as exc:
        raise ParameterError(f"{option} {str(path)!r}: cannot write it ({exc.strerror})") from exc


def make_output_folder(path: str | Path, option: str) -> Path:
    """Make an output folder (and its parents) unless it exists; refuse one that cannot be.

    Runs on the main thread.

    Raises
    ------
    ParameterError
        The folder cannot be made (a file in the way, no permission, read-only).
    """
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(
            f"{option} {str(path)!r}: cannot make the folder ({exc.strerror})"
        ) from exc
    return path
