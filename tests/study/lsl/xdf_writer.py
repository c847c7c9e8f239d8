"""A small XDF writer for the tests (the format of the XDF 1.0 specification).

The file: `XDF:`, then chunks `[NumLengthBytes: 1, 4 or 8][Length: of Tag + Content,
little-endian][Tag: uint16][Content]`. Tag 1 FileHeader (XML), 2 StreamHeader
(StreamID uint32 + XML `<info>`), 3 Samples (StreamID, `[NumSampleBytes][NumSamples]`,
then per sample `[TimeStampBytes: 0 or 8][TimeStamp: double][values]`, a string value
as `[NumLengthBytes][Length][bytes]`), 4 ClockOffset (StreamID, CollectionTime and
OffsetValue as doubles), 6 StreamFooter (StreamID + XML). Written here because pyxdf
only reads XDF and LabRecorder (which writes it) is a desktop application; written
independently of the reader, so a test that reads these files back checks both sides.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape

FORMATS = {"double64": "<d", "float32": "<f", "int32": "<i", "string": None}


def _varlen(n: int) -> bytes:
    if n < 256:
        return bytes([1]) + struct.pack("<B", n)
    if n < 2**32:
        return bytes([4]) + struct.pack("<I", n)
    return bytes([8]) + struct.pack("<Q", n)


def _chunk(tag: int, content: bytes) -> bytes:
    return _varlen(len(content) + 2) + struct.pack("<H", tag) + content


@dataclass
class XdfStream:
    name: str
    type: str
    channel_format: str
    nominal_srate: float
    channels: list[tuple[str, str]]
    """(label, unit) per channel."""
    stamps: list[float]
    values: list[list[object]]
    source_id: str = ""
    clock_offsets: list[tuple[float, float]] = field(default_factory=list)
    """(collection time, offset value): the offset pyxdf adds to the stamps."""

    def header(self) -> str:
        channels = "".join(
            f"<channel><label>{escape(label)}</label><unit>{escape(unit)}</unit></channel>"
            for label, unit in self.channels
        )
        return (
            f'<?xml version="1.0"?><info><name>{escape(self.name)}</name>'
            f"<type>{escape(self.type)}</type><channel_count>{len(self.channels)}"
            f"</channel_count><nominal_srate>{self.nominal_srate}</nominal_srate>"
            f"<channel_format>{self.channel_format}</channel_format>"
            f"<source_id>{escape(self.source_id)}</source_id>"
            f"<created_at>0</created_at><desc><channels>{channels}</channels></desc></info>"
        )

    def samples(self, stream_id: int) -> bytes:
        out = [struct.pack("<I", stream_id), _varlen(len(self.stamps))]
        fmt = FORMATS[self.channel_format]
        for stamp, row in zip(self.stamps, self.values, strict=True):
            out.append(bytes([8]) + struct.pack("<d", stamp))
            for v in row:
                if fmt is None:
                    raw = str(v).encode()
                    out.append(_varlen(len(raw)) + raw)
                else:
                    out.append(struct.pack(fmt, v))
        return b"".join(out)

    def footer(self) -> str:
        offsets = "".join(
            f"<offset><time>{t}</time><value>{v}</value></offset>" for t, v in self.clock_offsets
        )
        first = self.stamps[0] if self.stamps else 0
        last = self.stamps[-1] if self.stamps else 0
        return (
            f'<?xml version="1.0"?><info><first_timestamp>{first}</first_timestamp>'
            f"<last_timestamp>{last}</last_timestamp><sample_count>{len(self.stamps)}"
            f"</sample_count><clock_offsets>{offsets}</clock_offsets></info>"
        )


def write_xdf(path: Path, streams: list[XdfStream]) -> Path:
    """Write `streams` as LabRecorder would: headers, samples, clock offsets, footers."""
    parts = [b"XDF:", _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')]
    for k, s in enumerate(streams, start=1):
        parts.append(_chunk(2, struct.pack("<I", k) + s.header().encode()))
    for k, s in enumerate(streams, start=1):
        if s.stamps:
            parts.append(_chunk(3, s.samples(k)))
        for t, v in s.clock_offsets:
            parts.append(_chunk(4, struct.pack("<I", k) + struct.pack("<dd", t, v)))
    for k, s in enumerate(streams, start=1):
        parts.append(_chunk(6, struct.pack("<I", k) + s.footer().encode()))
    path.write_bytes(b"".join(parts))
    return path
