"""Export of the lab's other instruments' streams beside the trials' samples.

`study export --samples` writes, besides the trials' own samples, one file per recorded
stream (`streams/<stream name>.csv` or `.parquet`, by the stream's LSL name): the key
columns of the trial (participant, task, condition, trial), `seq` within the trial's
stream, `t_s` on the trial's clock, `lsl_time_s` (the source's stamp), then the
stream's channels under their own names. The codebook names every channel as
`<stream name>/<channel>` with its unit. The selection's participants, tasks,
conditions, trials and time range apply as to the samples. Streams are read whole per
trial (an instrument's trial is small beside the study's samples).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from sqlalchemy import Engine

from db.lsl_streams import read_stream, trial_streams
from study.protocol.export_files import AtomicFile, escape_array

if TYPE_CHECKING:
    from study.protocol.sample_export import ExportTrial, SampleSelection

KEY_COLUMNS = ("participant", "task", "condition", "trial", "seq")
STREAM_CODEBOOK = {
    "seq": ("", "sample number within the trial's stream"),
    "t_s": ("s", "time on the trial's clock (0 at its start)"),
    "lsl_time_s": ("s", "the instrument's own LSL time stamp"),
}


def file_name(stream: str, fmt: str) -> str:
    """`EMG-Delsys.csv`: the stream's name, characters a file name cannot hold replaced."""
    return re.sub(r"[^A-Za-z0-9_.-]", "-", stream).strip(".") + f".{fmt}"


@dataclass
class StreamExport:
    """The stream files to write and the codebook's lines for their channels."""

    tables: dict[str, list[pa.Table]] = field(default_factory=dict)
    codebook: dict[str, tuple[str, str]] = field(default_factory=dict)


def collect_streams(
    engine: Engine, trials: list[ExportTrial], selection: SampleSelection
) -> StreamExport:
    """Every stored stream of `trials`, keyed, within the selection's time range."""
    out = StreamExport()
    by_id = {t.trial_id: t for t in trials}
    for stream in trial_streams(engine, list(by_id)):
        trial = by_id[stream.trial_id]
        table = read_stream(engine, stream.id)
        n = table.num_rows
        seq = pa.array(np.arange(n, dtype=np.int64))
        keys = [
            pa.array([trial.participant] * n, pa.string()),
            pa.array([trial.task] * n, pa.string()),
            pa.array([trial.condition] * n, pa.string()),
            pa.array([trial.trial] * n, pa.int64()),
            seq,
        ]
        keyed = pa.Table.from_arrays(
            [*keys, *table.columns], names=[*KEY_COLUMNS, *table.column_names]
        )
        t = keyed["t_s"].to_numpy()
        keep = np.ones(n, dtype=bool)
        if selection.from_s is not None:
            keep &= t >= selection.from_s
        if selection.to_s is not None:
            keep &= t < selection.to_s
        out.tables.setdefault(stream.name, []).append(keyed.filter(pa.array(keep)))
        for ch in stream.channels:
            meaning = f"stream {stream.name} (LSL type {stream.type}): channel {ch['name']}"
            out.codebook.setdefault(f"{stream.name}/{ch['name']}", (ch["unit"], meaning))
    return out


def write_streams(export: StreamExport, folder: Path, fmt: str) -> list[AtomicFile]:
    """Stage one file per stream in `folder` (committed by the caller with the rest)."""
    staged: list[AtomicFile] = []
    if not export.tables:
        return staged
    folder.mkdir(exist_ok=True)
    for name, tables in export.tables.items():
        table = pa.concat_tables(tables, promote_options="default")
        out = AtomicFile(folder / file_name(name, fmt))
        staged.append(out)
        if fmt == "csv":
            text = pa.Table.from_arrays(
                [
                    escape_array(c.combine_chunks()) if pa.types.is_string(c.type) else c
                    for c in table.columns
                ],
                names=table.column_names,
            )
            pa_csv.write_csv(text, out.file)
        else:
            pq.write_table(table, out.file)
    return staged
