"""Errors that jaxcnc reports to users.

Every error a user can cause (a bad program, a bad machine file, a damaged table) is a
:class:`JaxcncError` whose message names the file, the place in it and the cause. The
command line prints that message and exits non-zero; it never prints a traceback for them.
"""

from __future__ import annotations


class JaxcncError(Exception):
    """Base class of every error caused by input rather than by a bug."""


class SourceError(JaxcncError):
    """An error located in a text source (G-code program): ``file:line:column: message``.

    Attributes:
        file: path (or name) of the source.
        line: 1-based line number, or 0 when the error concerns the whole file.
        column: 1-based column, or 0 when unknown.
        reason: what is wrong, without the location.
    """

    def __init__(self, file: str, line: int, column: int, reason: str):
        self.file, self.line, self.column, self.reason = str(file), int(line), int(column), reason
        where = self.file
        if line:
            where += f":{line}"
            if column:
                where += f":{column}"
        super().__init__(f"{where}: {reason}")


class MachineFileError(JaxcncError):
    """A mistake in a machine description: names the file, the key (dotted path) and the reason."""

    def __init__(self, file: str, key: str, reason: str, line: int = 0):
        self.file, self.key, self.reason, self.line = str(file), key, reason, line
        where = f"{self.file}:{line}" if line else self.file
        super().__init__(f"{where}: [{key}] {reason}" if key else f"{where}: {reason}")


class PlanningError(JaxcncError):
    """The program cannot be executed on this machine (outside travel, axis missing, ...)."""


class RowPlanningError(PlanningError):
    """A :class:`PlanningError` of one program row, raised where the program's file and lines are not known (a
    planner sees spans): :func:`~jaxcnc.planners.plan_job` names the row's file and line.

    Attributes:
        row: the program row.
        reason: what is wrong, without the location.
        per_row: optional amounts per program row, of which the row's source line has the most (an arc's P turns
            are rows of one line): ``plan_job`` names that line instead, and ``reason``'s ``{on_line}`` becomes
            its amount.
    """

    def __init__(self, row: int, reason: str, per_row=None):
        self.row, self.reason, self.per_row = int(row), reason, per_row
        super().__init__(f"program row {self.row}: {reason}")


class TableFileError(JaxcncError):
    """A tick table file that is damaged, truncated or not a table file at all."""
