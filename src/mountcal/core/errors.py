"""The one exception hierarchy of mountcal.

Every error a user can cause is a :class:`MountcalError`; the CLI prints its message and exits
non-zero without a traceback. Messages say where, what was expected, what was found and what to do.
"""

from __future__ import annotations

from typing import NoReturn

from mountcal.core.option_names import option


class MountcalError(Exception):
    """Base of every error mountcal raises on purpose."""

    exit_code = 2


class InputError(MountcalError):
    """A file or table is unreadable, malformed or physically implausible."""

    def __init__(self, where: str, expected: str, found: str, todo: str) -> None:
        self.where, self.expected, self.found, self.todo = where, expected, found, todo
        super().__init__(f"{where}: expected {expected}, found {found}. {todo}")


class NotEnoughInformation(MountcalError):
    """The data cannot determine what was asked (too few stops, one heading, ...)."""

    exit_code = 3


class FitFailed(MountcalError):
    """The estimator did not converge or returned a non-finite answer."""

    exit_code = 4


def refuse_not_confident(where: str, found: str, todo: str) -> NoReturn:
    """The one refusal of ``require_confident`` (``rotate`` and ``fleet``): ``found`` the results that are not
    confident, ``todo`` what to do besides accepting them."""
    raise InputError(
        where,
        f"a confident calibration ({option('require_confident', True)})",
        found,
        f"{todo}, or drop {option('require_confident', True)} (accept results that are not confident).",
    )
