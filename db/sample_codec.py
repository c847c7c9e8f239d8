"""How a chunk of samples is stored: one row of `sample_chunks` per committed second.

A trial's samples are stored per chunk (what `SampleWriter` commits at once, at most a
second of trial time) as one compressed Arrow record batch, not as a row per sample:
a row per sample took more than twice the bytes in SQLite and a driver call per value
to read back, which held the Parquet export below a million samples a second; a chunk
decodes at several million samples a second, and the writer binds one row per second
instead of a thousand (`study bench export`; the figures are on the Benchmarks page).

The format, for anyone reading a study database without this package:

- `data` is the zstd-compressed Arrow IPC *message* of one record batch (no schema
  message) whose schema is the row of `sample_schemas` that `schema_id` names: an Arrow
  IPC schema message (`pyarrow.ipc.read_schema`), the trial's task's own sample columns
  in the task's order, `t_s` float64 not null first, text columns utf8, every other
  column float64 (NULL where a value is missing), each field's metadata holding its
  `unit` and `description`;
- `raw_bytes` is the message's size before compression;
- sample `k` of the chunk has `seq = first_seq + k`.

In Python: `pyarrow.ipc.read_record_batch(pyarrow.decompress(data, raw_bytes,
codec="zstd"), pyarrow.ipc.read_schema(pyarrow.py_buffer(schema_data)))`. Chunks
still in `CHUNK_SCHEMA`, the one layout all trials had before revision 0006
(`SAMPLE_COLUMNS`), are those of a task revision 0010 did not know, or of a writer
given no schema: they are read by their column names. The message without its schema (which
is stored once per distinct schema, not in every chunk) keeps a 100-sample chunk (a
100 Hz trial's second) at about 48 bytes a sample, against 80 with a schema in every
chunk, and decodes three times faster. pyarrow does the encoding, compression and
decoding; what is written here is only which columns go where.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from db.errors import DbInputError
from db.models.trial import SAMPLE_COLUMNS

CODEC = "zstd"

CHUNK_SCHEMA = pa.schema(
    [
        pa.field(name, pa.string() if name == "branch" else pa.float64(), name != "t_s")
        for name in SAMPLE_COLUMNS
    ]
)
"""The legacy chunk schema (`SAMPLE_COLUMNS`, no key: the chunk's row holds it), and the
schema of a writer given none."""


def sample_field(name: str, unit: str, description: str, *, text: bool = False) -> pa.Field:
    """One column of a chunk schema: float64 (utf8 if `text`), its unit and description
    in the field's metadata; `t_s` is the one column that may not be NULL."""
    return pa.field(
        name,
        pa.string() if text else pa.float64(),
        name != "t_s",
        metadata={"unit": unit, "description": description},
    )


def check_schema(schema: pa.Schema) -> pa.Schema:
    """`schema` if it can be a chunk's: `t_s` (float64) first, names unique, each field
    float64 or utf8; else one line saying what is wrong."""
    names = schema.names
    if not names or names[0] != "t_s" or schema.field(0).type != pa.float64():
        raise DbInputError(f"sample schema {names}; expected 't_s' (float64) as its first column")
    if len(set(names)) != len(names):
        raise DbInputError(f"sample schema {names} names a column twice")
    for field in schema:
        if field.type not in (pa.float64(), pa.string()):
            raise DbInputError(
                f"sample column {field.name!r} of type {field.type}; expected float64 or utf8"
            )
    return schema


def schema_bytes(schema: pa.Schema) -> bytes:
    """`schema` as stored in `sample_schemas.data` (an Arrow IPC schema message)."""
    return schema.serialize().to_pybytes()


def schema_fingerprint(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_schema(data: bytes) -> pa.Schema:
    """The schema stored as `data` in `sample_schemas`."""
    return pa.ipc.read_schema(pa.py_buffer(data))


def column_array(
    name: str,
    values: Sequence[object] | np.ndarray | pa.Array | None,
    n: int,
    schema: pa.Schema = CHUNK_SCHEMA,
) -> pa.Array:
    """`values` of sample column `name` as the chunk's Arrow type; NaN and None are NULL.

    A column not given (`values` None) is all NULL. A value that is not a number (or,
    for `branch`, not text) is refused with a line naming the column.
    """
    field = schema.field(name)
    if values is None:
        return pa.nulls(n, field.type)
    try:
        if field.type == pa.string():
            return pa.array(values, type=pa.string(), from_pandas=True)
        return pa.array(np.asarray(values, dtype=np.float64), from_pandas=True)
    except (TypeError, ValueError, pa.ArrowException) as exc:
        expected = "text (a branch name) or None" if field.type == pa.string() else "a number"
        raise DbInputError(
            f"sample column {name!r} has a value that is not {expected} ({exc})"
        ) from None


def encode(batch: pa.RecordBatch) -> tuple[bytes, int]:
    """The stored form of `batch` (`CHUNK_SCHEMA`): compressed bytes and their raw size."""
    message = batch.serialize()
    return pa.compress(message, codec=CODEC, asbytes=True), message.size


def decode(data: bytes, raw_bytes: int, schema: pa.Schema = CHUNK_SCHEMA) -> pa.RecordBatch:
    """The record batch stored as `data` (see the module's description of the format)."""
    message = pa.decompress(data, decompressed_size=raw_bytes, codec=CODEC)
    return pa.ipc.read_record_batch(message, schema)
