"""Parquet files grown by one row group per save, without rewriting the row groups they hold.

LeRobot keeps a pq.ParquetWriter open on a session's data file and closes it when the session
ends: until then the file has no footer and cannot be read, so a crash loses the whole session.
Here every save leaves a whole file: the episode's row group is written where the old footer
began, followed by a footer that lists every row group (the old footer's and the new one), and
commit.py makes that change in place undoable (a Splice). A save thus writes the episode's rows
and the footer, not the file (the footer grows by about 1 kB per episode: its row groups' index).

pyarrow's ParquetWriter encodes the row group, but it starts only at the beginning of its sink
("Appending to file not implemented") and counts the offsets its footer records from there. So
it writes into a scratch file, seeked to where the row group will lie in the real file: its
offsets are then the file's. The scratch file is sparse: only the pages written take room.
"""

from __future__ import annotations

import os
import struct
import tempfile
from dataclasses import dataclass

import pyarrow as pa
import pyarrow.parquet as pq

from so101.dataset.commit import Splice

MAGIC = b"PAR1"
_FOOTER_TRAILER_BYTES = 8  # the footer's length (int32, little-endian), then MAGIC


@dataclass(frozen=True)
class ParquetEnd:
    """A parquet file's last bytes, as this writer left them: where its footer starts, and the
    footer with its length and MAGIC."""

    footer_start: int
    footer: bytes


def new_file(table: pa.Table) -> tuple[bytes, ParquetEnd]:
    """A parquet file of `table` as one row group: its bytes, and its end to append to."""
    row_group, footer = _row_group_at(table, len(MAGIC))
    return MAGIC + row_group + footer, ParquetEnd(len(MAGIC) + len(row_group), footer)


def appended(path: str, end: ParquetEnd, table: pa.Table) -> tuple[Splice, ParquetEnd]:
    """`table` as one more row group of the file at `path` whose end is `end`: the change, and
    the file's end after it."""
    row_group, footer = _row_group_at(table, end.footer_start)
    metadata = _metadata(end.footer)
    metadata.append_row_groups(_metadata(footer))
    sink = pa.BufferOutputStream()
    metadata.write_metadata_file(sink)  # MAGIC, then the footer as it ends a file
    combined = sink.getvalue().to_pybytes()[len(MAGIC):]
    return Splice(path, end.footer_start, row_group + combined), ParquetEnd(end.footer_start + len(row_group), combined)


def _metadata(footer: bytes) -> pq.FileMetaData:
    return pq.read_metadata(pa.BufferReader(MAGIC + footer))


def _row_group_at(table: pa.Table, offset: int) -> tuple[bytes, bytes]:
    """`table` encoded as the row group that starts `offset` bytes into a file, and the footer of
    a file that holds just it (offsets as in that file)."""
    # A temporary file, not a memfd: the same on Linux and macOS.
    with tempfile.NamedTemporaryFile(prefix="so101-row-group-") as scratch_file:
        # Room for the row group and its footer; untouched pages cost nothing, so a loose bound
        # will do: dictionary and snappy encodings do not grow data past twice its size, and the
        # footer and page headers take kilobytes.
        os.ftruncate(scratch_file.fileno(), offset + 3 * table.nbytes + (1 << 20))
        with pa.memory_map(scratch_file.name, "r+") as scratch:
            with pq.ParquetWriter(scratch, table.schema, compression="snappy", use_dictionary=True) as writer:
                scratch.seek(offset)  # the writer wrote its MAGIC at 0
                writer.write_table(table)
            end = scratch.tell()
            scratch.seek(end - _FOOTER_TRAILER_BYTES)
            footer_start = end - _FOOTER_TRAILER_BYTES - struct.unpack("<i", scratch.read(4))[0]
            scratch.seek(offset)
            row_group = scratch.read(footer_start - offset)
            footer = scratch.read(end - footer_start)
        return row_group, footer
