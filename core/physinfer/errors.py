"""Exceptions with messages meant for users.

The CLI prints a :class:`UserInputError` as one clear line (what was wrong, how to fix
it) and exits with status 2, never with a traceback. Anything else is a bug.
"""

from __future__ import annotations


class PhysinferError(Exception):
    """Base class of physinfer's own errors."""


class UserInputError(PhysinferError, ValueError):
    """Bad input from the user: a file, an option, a parameter value.

    Args:
        message: What was wrong (with the remedy, or without it when ``remedy`` is given).
        remedy: How to fix it, when the caller keeps it apart: the message printed is
            ``"{message}; {remedy}"``, and code that reports only why something does not
            apply (``refine`` searching without a posterior) reads :attr:`reason`.
    """

    def __init__(self, message: str = "", *, remedy: str | None = None) -> None:
        self.reason = message
        self.remedy = remedy
        super().__init__(f"{message}; {remedy}" if remedy else message)


class ResumeMismatch(UserInputError):
    """A run asked to continue was made with other settings; :attr:`shown` lists what differs
    (``--seed: run 0, now 1``), so a command that resumes runs of its own (``diagnose``'s
    stages) can say it in its own words and with its own remedy."""

    def __init__(self, message: str, shown: str = "", *, remedy: str | None = None) -> None:
        self.shown = shown
        super().__init__(message, remedy=remedy)


class SimulationFailed(PhysinferError, RuntimeError):
    """A simulation raised, produced NaN or blew up; the refinement records a failed trial."""


class NothingMoves(UserInputError):
    """A clip in which no subject can be tracked (nothing moves, or it leaves the view).

    About a user's video it is said in one line; a motion embedder turns a simulation's
    (a swing too small to see) into the embedding of stillness instead.
    """
