"""How a chunk of samples is stored: one row of `sample_chunks` per committed second.

A trial's samples are stored per chunk (what `SampleWriter` commits at once, at most a
second of trial time) as one compressed Arrow record batch, not as a row per sample:
a row per sample took more than twice the bytes in SQLite and a driver call per value
to read back, which held the Parquet export below a million samples a second; a chunk
decodes at several million samples a second, and the writer binds one row per second
instead of a thousand (`study bench export`; the figures are on the Benchmarks page).

The format, for anyone reading a study database without this package:

- `data` is the zstd-compressed Arrow IPC *message* of one record batch (no schema
  message) whose schema is the row of `sample_schemas` that `schema_id` names (every
  chunk names one): an Arrow IPC schema message (`pyarrow.ipc.read_schema`), the
  trial's task's own sample columns in the task's order, `t_s` float64 not null first,
  text columns utf8, every other column float64 (NULL where a value is missing), each
  field's metadata holding its `unit` and `description`;
- `raw_bytes` is the message's size before compression;
- sample `k` of the chunk has `seq = first_seq + k`.

In Python: `pyarrow.ipc.read_record_batch(pyarrow.decompress(data, raw_bytes,
codec="zstd"), pyarrow.ipc.read_schema(pyarrow.py_buffer(schema_data)))`.

One schema row is not a task's: the layout all trials had before revision 0006 (`t_s`,
`insertion_m`, `rotation_rad`, `tip_x_m`, `tip_y_m`, `tip_z_m`, `branch` utf8,
`proximal_force_n`, `proximal_force_est_n`, `distal_force_n`, `dial_angle_rad`,
`dial_torque_n_m`; no field metadata). The upgrades moved the chunks of the tasks they
knew to those tasks' own names (revisions 0006 and 0010); chunks of any other task keep
that layout and are read, like every chunk, by their stored schema.

The message without its schema (which is stored once per distinct schema, not in every
chunk) keeps a 100-sample chunk (a 100 Hz trial's second) at about 48 bytes a sample,
against 80 with a schema in every chunk, and decodes three times faster. pyarrow does
the encoding, compression and decoding; what is written here is only which columns go
where.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from db.errors import DbInputError

CODEC = "zstd"


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
    schema: pa.Schema,
) -> pa.Array:
    """`values` of sample column `name` as its Arrow type in `schema`; NaN and None are NULL.

    A column not given (`values` None) is all NULL. A value that is not a number (or,
    for a text column, not text) is refused with a line naming the column.
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
    """The stored form of `batch` (its schema is stored apart, `schema_bytes`):
    compressed bytes and their raw size."""
    message = batch.serialize()
    return pa.compress(message, codec=CODEC, asbytes=True), message.size


def decode(data: bytes, raw_bytes: int, schema: pa.Schema) -> pa.RecordBatch:
    """The record batch stored as `data` in `schema`, the chunk's stored schema (see the
    module's description of the format)."""
    message = pa.decompress(data, decompressed_size=raw_bytes, codec=CODEC)
    return pa.ipc.read_record_batch(message, schema)
