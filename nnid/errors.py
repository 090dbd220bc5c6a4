"""The one error type for bad user input: it names where the problem is and what was expected."""

from __future__ import annotations


class NnidInputError(ValueError):
    """Bad input (a file, a field, a column or a row) with a message a person can act on.

    The CLI turns it into one line on stderr and exit code 2.
    """

    def __init__(
        self,
        message: str,
        *,
        source: str | None = None,
        field: str | None = None,
        row: int | None = None,
    ) -> None:
        self.message = message
        self.source = source
        self.field = field
        self.row = row
        where = []
        if source:
            where.append(str(source))
        if field:
            where.append(f"field '{field}'" if row is None else f"column '{field}'")
        if row is not None:
            where.append(f"row {row}")
        prefix = ", ".join(where) + ": " if where else ""
        super().__init__(prefix + message)

    def with_source(self, source: str) -> NnidInputError:
        """The same error, naming ``source`` if it named no file yet."""
        if self.source is not None:
            return self
        return NnidInputError(self.message, source=source, field=self.field, row=self.row)
