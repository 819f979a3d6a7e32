"""Text formats of the tables (flux table, convergence study): one set of rules.

Nothing here imports numpy, so the command line can pick a format by the
output file's extension before loading anything.
"""
from __future__ import annotations

import csv
import io
import json
import math
import numbers
from pathlib import Path

from markov.errors import InvalidParameterError

__all__ = ["FORMATS", "RenderedTable", "format_for_path", "csv_cell", "csv_number",
           "plus_minus"]

#: Formats of :meth:`RenderedTable.render` (and ``--format``).
FORMATS = ("text", "csv", "md", "latex", "json")
_BY_EXTENSION = {".csv": "csv", ".md": "md", ".tex": "latex", ".json": "json", ".txt": "text"}


class RenderedTable:
    """A table that renders itself in every format of :data:`FORMATS` (``to_<format>``).

    A subclass provides ``to_dict``, the text formats and :meth:`records`,
    one flat dict per row, from which both the CSV and the pandas DataFrame
    are made (the same columns, the same numbers).
    """

    def records(self) -> list[dict]:
        """One flat dict per row (column -> number, string or None), in column order.

        Returns
        -------
        list of dict
        """
        raise NotImplementedError

    def to_csv(self) -> str:
        """The table as CSV, one line per row of :meth:`records`, numbers in full precision.

        Returns
        -------
        str
        """
        rows = self.records()
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(list(rows[0]) if rows else [])
        for r in rows:
            w.writerow([csv_cell(x) for x in r.values()])
        return buf.getvalue()

    def to_frame(self):
        """The table as a pandas DataFrame, one row per row of :meth:`records`.

        Returns
        -------
        pandas.DataFrame
        """
        import pandas as pd

        rows = self.records()
        frame = pd.DataFrame.from_records(rows, columns=list(rows[0]) if rows else None)
        for name in frame.columns:   # a number column with gaps: floats with NaN
            values = [x for x in frame[name] if x is not None]
            if all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in values):
                frame[name] = pd.to_numeric(frame[name].astype(object).where(
                    frame[name].notna(), float("nan")))
        return frame

    def to_json(self) -> str:
        """The table as indented JSON (of ``to_dict()``).

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def render(self, fmt: str = "text") -> str:
        """The table as text in one of :data:`FORMATS`.

        Parameters
        ----------
        fmt : {"text", "csv", "md", "latex", "json"}

        Returns
        -------
        str
        """
        if fmt not in FORMATS:
            raise InvalidParameterError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
        return getattr(self, f"to_{fmt}")()


def format_for_path(path) -> str:
    """The format implied by an output file's extension; ``text`` otherwise (or for None).

    Parameters
    ----------
    path : str, os.PathLike or None

    Returns
    -------
    str

    Examples
    --------
    >>> format_for_path("flux.tex"), format_for_path(None)
    ('latex', 'text')
    """
    return _BY_EXTENSION.get(Path(path).suffix.lower(), "text") if path else "text"


def csv_cell(x) -> str:
    """A CSV cell: empty for None, ``true``/``false``, an int as is, a float by
    :func:`csv_number`, text as it is.

    Parameters
    ----------
    x : None, bool, int, float or str

    Returns
    -------
    str

    Examples
    --------
    >>> [csv_cell(x) for x in (None, True, 6, 0.1, float("inf"), "a b")]
    ['', 'true', '6', '0.1', 'inf', 'a b']
    """
    if x is None:
        return ""
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, numbers.Integral):
        return str(int(x))
    if isinstance(x, numbers.Real):
        return csv_number(x)
    return str(x)


def csv_number(x) -> str:
    """A number in a CSV cell: its ``repr`` (round-trips exactly), empty for None.

    Parameters
    ----------
    x : float or None

    Returns
    -------
    str
    """
    return "" if x is None else repr(float(x))


def plus_minus(value: float, error: float | None, latex: bool) -> str:
    """``value ± error`` with the error rounded to two significant digits.

    Parameters
    ----------
    value : float
    error : float or None
        No error (None, 0, not finite): the value alone, six decimals.
    latex : bool
        ``$\\pm$`` instead of ``±``.

    Returns
    -------
    str

    Examples
    --------
    >>> plus_minus(0.123456, 0.00123, latex=False)
    '0.1235 ± 0.0012'
    """
    if error is None or not math.isfinite(error) or error <= 0:
        return f"{value:.6f}"
    digits = max(0, min(8, 1 - int(math.floor(math.log10(error)))))
    sep = r" $\pm$ " if latex else " ± "
    return f"{value:.{digits}f}{sep}{error:.{digits}f}"
