"""`study import-xdf` fuzzed: recordings made wrong one way at a time, by family.

A valid one-trial recording (the project's markers and a two-channel EMG stream, written
by `xdf_writer` independently of pyxdf) is the seed; each case changes one thing of it:

- a marker field of the `trial_start` or the `trial_end` dropped, or given a value of
  another JSON type or out of range;
- a stream header that disagrees with its data (channel count, channel format of another
  width, a marker stream declared numeric) or holds a rate that is no number;
- a sample time stamp or a clock offset that is not finite;
- the markers out of order, repeated, or a trial's end naming other keys than its start;
- a footer counting other than the samples there are;
- the file cut short at any byte.

Each: exit status 2, one line on stderr naming the recording, nothing on stdout, no
traceback (pyxdf's own log included), and every table of the database with the rows it
had. The unchanged seed imports (so a refusal is the mutation's). Draws are deterministic;
`STUDY_FUZZ_EXAMPLES=2000` runs more of each family.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sqlite3
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from db.models.trial import Trial
from study.cli import main
from study.lsl.markers import KEY, MARKER_STREAM, VERSION
from study.lsl.xdf import TRIAL_FIELDS
from tests.study.lsl.test_import_xdf import _emg, study_db
from tests.study.lsl.test_import_xdf_faults import _keys
from tests.study.lsl.xdf_writer import XdfStream, write_xdf

__all__ = ["study_db"]  # the fixture, shared with the import's own tests

EXAMPLES = int(os.environ.get("STUDY_FUZZ_EXAMPLES", "0") or 0)
FAST = settings(
    deadline=None, suppress_health_check=list(HealthCheck), derandomize=True, database=None
)


def _examples(ci: int) -> int:
    return EXAMPLES or ci


class Mutated(XdfStream):
    """A stream whose header or footer text has edits (old, new) applied, so that it
    declares other than its data hold."""

    header_edits: tuple[tuple[str, str], ...] = ()
    footer_edits: tuple[tuple[str, str], ...] = ()

    @classmethod
    def of(
        cls,
        stream: XdfStream,
        header: Iterable[tuple[str, str]] = (),
        footer: Iterable[tuple[str, str]] = (),
    ) -> Mutated:
        new = cls(**{k: getattr(stream, k) for k in stream.__dataclass_fields__})
        new.header_edits, new.footer_edits = tuple(header), tuple(footer)
        return new

    def header(self) -> str:
        text = super().header()
        for old, new in self.header_edits:
            assert old in text, old
            text = text.replace(old, new)
        return text

    def footer(self) -> str:
        text = super().footer()
        for old, new in self.footer_edits:
            assert old in text, old
            text = text.replace(old, new)
        return text


_DROP = object()


def _not_one_trial(events: list[tuple[float, str]]) -> bool:
    """Any marker sequence but a start then its end (or a start alone: a crashed trial),
    in the order the import reads them: by stamp, a tie in the stream's order."""
    order = [e for _, e in sorted(events, key=lambda te: te[0])]
    return order not in (["trial_start", "trial_end"], ["trial_start"])


class TestMutatedRecordings:
    """Each family of mutation of a valid recording is refused whole (module docstring)."""

    # -- the seed and the check ---------------------------------------------------------

    def streams(
        self,
        trial: Trial,
        start: dict[str, Any] | None = None,
        end: dict[str, Any] | None = None,
        events: list[tuple[float, str]] | None = None,
    ) -> tuple[XdfStream, XdfStream]:
        """The seed's marker and EMG streams; `start`/`end` replace marker fields
        (`_DROP` removes one), `events` the (stamp, event) sequence."""
        texts = {}
        for event, edits in (("trial_start", start), ("trial_end", end)):
            fields = {KEY: VERSION, "event": event, **_keys(trial), **(edits or {})}
            texts[event] = json.dumps({k: v for k, v in fields.items() if v is not _DROP})
        sequence = events or [(100.0, "trial_start"), (103.0, "trial_end")]
        markers = XdfStream(
            MARKER_STREAM,
            "Markers",
            "string",
            0.0,
            [("marker", "")],
            [t for t, _ in sequence],
            [[texts[e]] for _, e in sequence],
        )
        return markers, _emg(99.0, 1000)

    @staticmethod
    def rows(db: str) -> dict[str, int]:
        """Rows per table: what an import could have added."""
        with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as conn:
            names = [
                n
                for (n,) in conn.execute(
                    "SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name"
                )
            ]
            return {n: conn.execute(f'SELECT count(*) FROM "{n}"').fetchone()[0] for n in names}

    def refused(self, db: str, path: Path) -> str:
        before = self.rows(db)
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(["import-xdf", str(path), "--db", db])
        text = err.getvalue()
        lines = text.strip().splitlines()
        assert "Traceback" not in text, text
        assert code == 2, (code, text)
        assert len(lines) == 1, lines
        assert str(path) in lines[0], lines[0]
        assert out.getvalue() == ""
        assert self.rows(db) == before, "a refused import stored something"
        return lines[0]

    def test_the_seed_imports(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, capsys: pytest.CaptureFixture
    ) -> None:
        db, trials = study_db
        copy = tmp_path / "copy.db"
        with (
            contextlib.closing(sqlite3.connect(db)) as src,
            contextlib.closing(sqlite3.connect(copy)) as dst,
        ):
            src.backup(dst)
        path = write_xdf(tmp_path / "seed.xdf", list(self.streams(trials[0])))
        assert main(["import-xdf", str(path), "--db", str(copy)]) == 0
        assert "stored with 1 trial(s)" in capsys.readouterr().out
        assert self.rows(str(copy))["lsl_streams"] == 1

    # -- the families --------------------------------------------------------------------

    WRONG_VALUE = st.one_of(
        st.none(),
        st.booleans(),
        st.text(max_size=8),
        st.lists(st.integers(0, 3), max_size=2),
        st.dictionaries(st.sampled_from("ab"), st.integers(0, 3), max_size=1),
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(min_value=2**40),
        st.integers(max_value=-1),
        st.sampled_from([1e20, 1.5, -0.0, "1", "nan", "fast", "zero", "P001 "]),
    )

    @staticmethod
    def wrong_for(field: str, value: object) -> bool:
        """Whether `value` is not what `field` takes (some draws happen to be valid)."""
        _, ok = TRIAL_FIELDS[field]
        return not ok(value)

    @settings(FAST, max_examples=_examples(40))
    @given(
        event=st.sampled_from(["trial_start", "trial_end"]),
        field=st.sampled_from(sorted(TRIAL_FIELDS)),
        value=st.one_of(st.just(_DROP), WRONG_VALUE),
    )
    def test_a_marker_field_missing_or_wrong(
        self,
        study_db: tuple[str, list[Trial]],
        tmp_path: Path,
        event: str,
        field: str,
        value: object,
    ) -> None:
        if value is not _DROP and not self.wrong_for(field, value):
            return
        db, trials = study_db
        edits = {field: value}
        start, end = (edits, None) if event == "trial_start" else (None, edits)
        path = write_xdf(tmp_path / "field.xdf", list(self.streams(trials[0], start, end)))
        line = self.refused(db, path)
        if value is _DROP:
            assert f"has no field {field!r}" in line, line
        else:
            assert f"{field} = " in line or "trial_end of trial_id" in line, line

    HEADER_EDITS = st.one_of(
        st.tuples(
            st.just("emg"),
            st.just("channel_count"),
            st.one_of(
                st.integers(0, 40).filter(lambda n: n != 2).map(str),
                st.sampled_from(["-1", "two", "", "2.5", str(2**40)]),
            ),
        ),
        st.tuples(
            st.just("emg"),
            st.just("channel_format"),
            # (not int64: of double64's width, its bytes read as valid whole numbers, and no
            # reader can tell)
            st.sampled_from(["float32", "int8", "int16", "int32", "string", "x"]),
        ),
        st.tuples(
            st.just("markers"),
            st.just("channel_format"),
            st.sampled_from(["float32", "double64", "int8", "int16", "int32", "int64"]),
        ),
        st.tuples(
            st.just("markers"),
            st.just("channel_count"),
            st.sampled_from(["0", "2", "3", "-1", "one"]),
        ),
        st.tuples(
            st.sampled_from(["emg", "markers"]),
            st.just("nominal_srate"),
            st.sampled_from(["nan", "inf", "-inf", "-5", "fast", ""]),
        ),
        st.tuples(
            st.sampled_from(["emg", "markers"]),
            st.sampled_from(["channel_count", "channel_format", "nominal_srate", "name"]),
            st.just(None),  # the element left out
        ),
    )

    @settings(FAST, max_examples=_examples(30))
    @given(edit=HEADER_EDITS)
    @example(edit=("emg", "nominal_srate", "nan"))
    @example(edit=("emg", "channel_count", "3"))
    @example(edit=("markers", "channel_format", "float32"))
    def test_a_header_that_disagrees_with_its_data(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, edit: tuple[str, str, Any]
    ) -> None:
        db, trials = study_db
        which, tag, value = edit
        markers, emg = self.streams(trials[0])
        stream = {"emg": emg, "markers": markers}[which]
        true = {
            "channel_count": str(len(stream.channels)),
            "channel_format": stream.channel_format,
            "nominal_srate": str(stream.nominal_srate),
            "name": stream.name,
        }[tag]
        element = f"<{tag}>{true}</{tag}>"
        replaced = "" if value is None else f"<{tag}>{value}</{tag}>"
        mutated = Mutated.of(stream, header=[(element, replaced)])
        pair = [mutated, emg] if which == "markers" else [markers, mutated]
        self.refused(db, write_xdf(tmp_path / "header.xdf", pair))

    @settings(FAST, max_examples=_examples(20))
    @given(
        which=st.sampled_from(["emg", "markers"]),
        what=st.sampled_from(["stamp", "offset"]),
        value=st.sampled_from([float("nan"), float("inf"), float("-inf")]),
        at=st.integers(0, 1),
    )
    def test_a_time_that_is_not_a_number(
        self,
        study_db: tuple[str, list[Trial]],
        tmp_path: Path,
        which: str,
        what: str,
        value: float,
        at: int,
    ) -> None:
        db, trials = study_db
        markers, emg = self.streams(trials[0])
        stream = {"emg": emg, "markers": markers}[which]
        if what == "stamp":
            stream.stamps = [value if k == at else t for k, t in enumerate(stream.stamps)]
        else:
            stream.clock_offsets = [(99.0, 0.25), (104.0, 0.25)]
            t, _ = stream.clock_offsets[at]
            stream.clock_offsets[at] = (t, value)
        line = self.refused(db, write_xdf(tmp_path / "time.xdf", [markers, emg]))
        assert "expected finite numbers of seconds" in line, line

    @settings(FAST, max_examples=_examples(20))
    @given(
        events=st.lists(
            st.tuples(st.floats(95.0, 110.0), st.sampled_from(["trial_start", "trial_end"])),
            min_size=1,
            max_size=4,
        ).filter(_not_one_trial)
    )
    def test_markers_out_of_order_or_repeated(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, events: list[tuple[float, str]]
    ) -> None:
        db, trials = study_db
        streams = list(self.streams(trials[0], events=events))
        line = self.refused(db, write_xdf(tmp_path / "order.xdf", streams))
        assert "is inconsistent" in line or "has no haptic-study trial markers" in line, line

    @settings(FAST, max_examples=_examples(16))
    @given(
        field=st.sampled_from(sorted(set(TRIAL_FIELDS) - {"trial_id"})),
        other=st.sampled_from([7, 2.0, True, "P002", "other study"]),
    )
    def test_an_end_that_names_another_trial(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, field: str, other: object
    ) -> None:
        db, trials = study_db
        if self.wrong_for(field, other):
            return  # a wrong value, not another trial: the field family's
        start = _keys(trials[0])[field]
        if other == start and type(other) is type(start):
            return
        streams = list(self.streams(trials[0], end={field: other}))
        line = self.refused(db, write_xdf(tmp_path / "end.xdf", streams))
        assert f"a trial_end of trial_id {trials[0].id} with {field} = " in line, line

    @settings(FAST, max_examples=_examples(10))
    @given(count=st.integers(0, 2000).filter(lambda n: n != 1000))
    def test_a_footer_counting_other_samples(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, count: int
    ) -> None:
        db, trials = study_db
        markers, emg = self.streams(trials[0])
        edit = ("<sample_count>1000</sample_count>", f"<sample_count>{count}</sample_count>")
        mutated = Mutated.of(emg, footer=[edit])
        line = self.refused(db, write_xdf(tmp_path / "footer.xdf", [markers, mutated]))
        assert f"footer counts {count}" in line, line

    @settings(FAST, max_examples=_examples(30))
    @given(fraction=st.floats(0.0, 1.0, exclude_max=True))
    def test_a_file_cut_short(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path, fraction: float
    ) -> None:
        db, trials = study_db
        whole = write_xdf(tmp_path / "whole.xdf", list(self.streams(trials[0]))).read_bytes()
        cut = tmp_path / "cut.xdf"
        cut.write_bytes(whole[: int(fraction * len(whole))])
        self.refused(db, cut)

    def test_a_marker_nested_deeper_than_json_reads(
        self, study_db: tuple[str, list[Trial]], tmp_path: Path
    ) -> None:
        db, trials = study_db
        markers, emg = self.streams(trials[0])
        deep = "[" * 100_000 + "]" * 100_000
        markers.values[0] = [markers.values[0][0][:-1] + f', "extra": {deep}}}']
        line = self.refused(db, write_xdf(tmp_path / "deep.xdf", [markers, emg]))
        assert "without its start" in line, line
