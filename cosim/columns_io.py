"""Named columns of a CSV or Parquet file, read only where used.

The one reader of the calibration's logs (:mod:`cosim.calibration.log`) and
of signal tables (:mod:`cosim.scenario.signal_table`). A file is data from anyone and may be
hours at hundreds of hertz with dozens of columns (issue 42 item 5), so
only its header (a CSV's first line, a Parquet file's footer) is read whole;
the columns a caller names are read by pyarrow -- a CSV streamed in blocks
of :data:`BLOCK` bytes with only those columns converted, a Parquet file's
column chunks of those columns alone -- and the memory a read takes is that
of those columns, not the file's. Every other column is tokenized (a CSV
row of another width is still refused) but never converted: a column the
caller does not use may hold anything.

A fault is one :class:`~cosim.errors.ScenarioError` line naming the file
(``where``), the row (``line_of(i)``, ``i`` the data row counted from 0:
each caller names rows its own way) and the column.
"""
from __future__ import annotations

import csv
import re
from typing import Callable, Iterator, Mapping, Sequence

import numpy as np

from .errors import ScenarioError, shown_text
from .files import repeated

__all__ = ["BLOCK", "MAX_HEADER_BYTES", "MAX_FOOTER_BYTES", "FieldError", "csv_header", "unique_columns", "csv_batches", "csv_floats",
           "parquet_schema", "parquet_read"]

BLOCK = 1 << 20  # bytes of a CSV parsed at a time: a row longer than this is refused by pyarrow
MAX_HEADER_BYTES = 1 << 20  # a CSV's header line, read before anything else
MAX_FOOTER_BYTES = 64 << 20  # a Parquet file's footer (its schema and metadata), read before any column

LineOf = Callable[[int], str]


class FieldError(ScenarioError):
    """A CSV field pyarrow could not convert to its column's type; ``column``
    names the column (so a caller may read it again another way)."""

    def __init__(self, message: str, column: str):
        super().__init__(message)
        self.column = column


def csv_header(path, where: str, errors: str = "strict") -> list[str]:
    """The fields of a CSV's first line as written (``[]`` for an empty
    file), at most :data:`MAX_HEADER_BYTES` read (``errors``: how bytes that
    are not UTF-8 are decoded, as :func:`open` takes it)."""
    try:
        with open(path, newline="", encoding="utf-8", errors=errors) as f:
            line = f.readline(MAX_HEADER_BYTES + 1)
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{where}: line 1: not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise ScenarioError(f"{where}: cannot be read ({exc.strerror or exc})") from None
    if len(line) > MAX_HEADER_BYTES:
        raise ScenarioError(f"{where}: a header line longer than {MAX_HEADER_BYTES} characters")
    try:
        return next(csv.reader([line]), [])
    except csv.Error as exc:
        raise ScenarioError(f"{where}: line 1: {exc}") from None


def unique_columns(names: Sequence[str], where: str) -> None:
    """Refuse two columns of one name: which of the two would be read? Neither, silently."""
    twice = repeated(list(names))
    if twice is not None:
        raise ScenarioError(f"{where}: two columns named {twice!r}; each name at most once")


def csv_batches(path, where: str, types: Mapping[str, object], header: Sequence[str], names: Sequence[str],
                line_of: LineOf, *, nulls: bool = True, max_rows: int | None = None,
                max_bytes: int | None = None) -> Iterator:
    """The CSV ``path`` as pyarrow record batches holding only the columns
    ``types`` names (raw header field -> Arrow type), streamed in blocks of
    :data:`BLOCK` bytes. ``header``: the raw fields, ``names``: what a
    message calls each. ``nulls``: pyarrow's null spellings (``""``,
    ``NA``, ...) read as null (a float's NaN); else an empty field is a
    value of its type (a String's ``""``), or not one. At most ``max_rows``
    rows and ``max_bytes`` bytes of the columns' data, else one line."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    convert = pcsv.ConvertOptions(include_columns=list(types), column_types=dict(types),
                                  **({} if nulls else {"null_values": [], "strings_can_be_null": False}))
    rows = held = 0
    try:
        # quoted fields may hold newlines (as the csv module reads them)
        for batch in pcsv.open_csv(path, read_options=pcsv.ReadOptions(block_size=BLOCK, use_threads=False),
                                   parse_options=pcsv.ParseOptions(newlines_in_values=True),
                                   convert_options=convert):
            rows += batch.num_rows
            held += batch.nbytes
            if max_rows is not None and rows > max_rows:
                raise ScenarioError(f"{where}: more than {max_rows} rows; at most {max_rows} are read")
            if max_bytes is not None and held > max_bytes:
                raise ScenarioError(f"{where}: more than {max_bytes} bytes of data in the columns used; at most "
                                    f"{max_bytes} are read")
            yield batch
    except (pa.ArrowInvalid, OSError, ValueError) as exc:  # a row of other width, a text value, not text
        said = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        at = re.match(r"In CSV column #(\d+): Row #(\d+): (.*)", said)
        if at is not None and int(at[1]) < len(names):  # pyarrow counts columns from 0, rows from the header
            column = names[int(at[1])]
            raise FieldError(f"{where}: {line_of(int(at[2]) - 2)}, column {column}: {shown_text(at[3], 200)}",
                             column) from None
        width = re.match(r"CSV parse error: Row #(\d+): Expected (\d+) columns, got (\d+)", said)
        if width is not None:
            said = f"{line_of(int(width[1]) - 2)}: {width[3]} fields for {width[2]} columns"
        raise ScenarioError(f"{where}: {shown_text(said, 200)}") from None


def csv_floats(path, where: str, raw: Mapping[str, str], header: Sequence[str], names: Sequence[str],
               line_of: LineOf, rows: int | None = None, **limits) -> dict[str, np.ndarray]:
    """The columns ``raw`` names (name -> raw header field) as float64
    arrays, in one pass over the file (:func:`csv_batches`, ``limits`` its
    keywords). With ``rows`` known (the time read first) each array is made
    once and filled in place, block by block: no second copy."""
    import pyarrow as pa

    out = {n: np.empty(rows) for n in raw} if rows is not None else {n: [] for n in raw}
    at = 0
    for batch in csv_batches(path, where, {r: pa.float64() for r in raw.values()}, header, names, line_of, **limits):
        for n, r in raw.items():
            block = batch.column(r).to_numpy(zero_copy_only=False)
            if rows is None:
                out[n].append(block)
            elif at + block.size <= rows:
                out[n][at:at + block.size] = block
        at += batch.num_rows
    if rows is not None and at != rows:  # the file changed between two reads
        raise ScenarioError(f"{where}: {at} rows now, {rows} when its time was read; the file changed")
    return {n: v if rows is not None else (np.concatenate(v) if v else np.zeros(0)) for n, v in out.items()}


def parquet_schema(path, where: str):
    """A Parquet file's schema and metadata, from its footer only: ``(schema, FileMetaData)``."""
    import pyarrow.parquet as pq

    try:  # the footer's length: its last 8 bytes, the length and b"PAR1" (else pyarrow says what is wrong)
        with open(path, "rb") as f:
            size = f.seek(0, 2)
            f.seek(max(size - 8, 0))
            tail = f.read(8)
    except OSError as exc:
        raise ScenarioError(f"{where}: cannot be read ({exc.strerror or exc})") from None
    if len(tail) == 8 and tail[4:] == b"PAR1" and int.from_bytes(tail[:4], "little") > MAX_FOOTER_BYTES:
        raise ScenarioError(f"{where}: a footer of {int.from_bytes(tail[:4], 'little')} bytes; at most "
                            f"{MAX_FOOTER_BYTES} are read")
    try:
        parquet = pq.ParquetFile(path)
        return parquet.schema_arrow, parquet.metadata
    except Exception as exc:  # pyarrow's errors are many types: the file is no Parquet we can read
        raise _not_parquet(where, exc) from None


def parquet_read(path, where: str, columns: Sequence[str]):
    """The Parquet file's ``columns`` (their column chunks alone) as a pyarrow table."""
    import pyarrow.parquet as pq

    try:
        return pq.read_table(path, columns=list(columns))
    except Exception as exc:
        raise _not_parquet(where, exc) from None


def _not_parquet(where: str, exc: Exception) -> ScenarioError:
    said = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return ScenarioError(f"{where}: not a Parquet file pyarrow reads ({shown_text(said, 200)})")
