"""Every limit the engine keeps, in one place (``docs/security.md`` states them).

Files from others are data; what they may ask for is bounded here, and each
bound is checked when the file is read, with a one-line refusal that names
the limit and what was asked.
"""
from __future__ import annotations

__all__ = ["MAX_DOCUMENT_BYTES", "MAX_ENTRY_BYTES", "MAX_ARCHIVE_BYTES", "MAX_RATIO", "MAX_STEPS",
           "MAX_RECORD_BYTES", "MAX_RUNS", "MAX_STATE", "SEED_LIMIT", "WORKER_TIMEOUT", "MAX_STRING_BYTES",
           "MAX_TABLE_ROWS", "MAX_TABLE_DATA", "MAX_NESTING", "MAX_GROUP"]

MAX_DOCUMENT_BYTES = 16 * 2 ** 20  # a scenario, study, learned-state file or SSD: far beyond any real one
MAX_ENTRY_BYTES = 512 * 2 ** 20  # one file extracted from an archive (an FMU's binary, an FMU in an SSP archive)
MAX_ARCHIVE_BYTES = 2 * 2 ** 30  # everything extracted from one archive
MAX_RATIO = 200  # uncompressed / compressed size of an entry (of more than 1 MiB): FMUs 3-10x, zip bombs 1000x
MAX_STEPS = 10 ** 9  # steps of one run: beyond, the step counter and the results outgrow any machine
MAX_RECORD_BYTES = 2 ** 30  # the rows a run keeps in memory when asked for every row (Master.run(keep=None)): 1 GiB,
# 16 h of 23 signals at 10 ms; a run that streams its rows (fnn-cosim run, studies) keeps a bounded few
MAX_RUNS = 1_000_000  # runs of one study: its runs.csv, its summary and its resume bitmap grow with them
MAX_STATE = 100_000  # values of a learned state
SEED_LIMIT = 2 ** 53  # a seed parameter is a double: every whole number up to 2^53 is exact
WORKER_TIMEOUT = 120.0  # s a study waits for a Dask cluster without a worker before it stops
MAX_STRING_BYTES = 2 ** 20  # one recorded String or Binary value; those a result keeps count against MAX_RECORD_BYTES
MAX_TABLE_ROWS = 10 ** 7  # rows of a signal table (its file is streamed: its size bounds no memory, its rows do)
MAX_TABLE_DATA = 2 ** 30  # the data of a signal table's columns read (a Parquet file's uncompressed, as its footer states: compressed it may be 1000x smaller)
MAX_NESTING = 32  # levels of a document (tables and arrays within each other) and parts of a dotted key (--set a.b.c): ours use 6; thousands exhaust the interpreter
MAX_GROUP = 10_000  # names in one brace group of a connection ({x,y,z}): ours hold 12; each is a connection checked
