"""The one error type for bad user input: it names where the problem is and what was expected;
and the warning of data that cannot identify what is asked of them."""

from __future__ import annotations

import math
from collections.abc import Container
from numbers import Real


class ExcitationWarning(UserWarning):
    """The data does not excite every parameter asked for (or bias its estimate); here, below
    every layer, as the data layer warns of it too (:func:`nnid.datasets.preprocess.preprocess`)."""


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

    def within(self, section: str, keys: Container[str]) -> NnidInputError:
        """The same error with its field named under ``section`` of a config (a model's
        ``output_bounds`` is ``model.output_bounds`` of a train config), if it names one of
        the section's ``keys`` (not a column, nor a key of a part below, such as a
        trainer's) and no file yet."""
        if self.source is not None or self.row is not None or self.field is None:
            return self
        if self.field.split(".")[0] not in keys:
            return self
        return NnidInputError(self.message, field=f"{section}.{self.field}")

    def with_source(self, source: str) -> NnidInputError:
        """The same error, naming ``source`` if it named no file yet, nor a command-line
        option (``--vehicle``): an option is no key of the file, which is then not at fault."""
        if self.source is not None or (self.field or "").startswith("--"):
            return self
        return NnidInputError(self.message, source=source, field=self.field, row=self.row)


def checked_number(
    value: object,
    field: str,
    minimum: float = 0.0,
    strict: bool = True,
    integer: bool = False,
    maximum: float = math.inf,
) -> float | int:
    """``value`` as a finite number above ``minimum`` (at or above it unless ``strict``) and
    at most ``maximum``, a whole one where ``integer``, or the error naming ``field``: a
    setting given in Python skips the config's checks, and a NaN, a 1.5-wide layer or a
    negative rate crashed deep in the fit (``int(nan)``, torch's optimiser) or trained as
    something else."""
    ok = isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (value > minimum if strict else value >= minimum) and value <= maximum
    if ok and integer:
        ok = float(value).is_integer()
    if not ok:
        kind = "a whole number" if integer else "a finite number"
        bound = f"{'above' if strict else 'at least'} {minimum:g}"
        if math.isfinite(maximum):  # a whole bound in full: 2³² − 1 read "4.29497e+09"
            top = int(maximum) if integer and float(maximum).is_integer() else f"{maximum:g}"
            bound += f" and at most {top}"
        raise NnidInputError(f"{kind} {bound} is expected, not {value!r}", field=field)
    return int(value) if integer else float(value)
