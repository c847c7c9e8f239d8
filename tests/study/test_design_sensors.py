"""The design's `[sensors]` table: read, kept through the database's design JSON, and a
bad one refused with one line naming the key and value."""

from __future__ import annotations

import pytest

from study.errors import StudyInputError
from study.protocol.design import StudyDesign, parse_design

DESIGN = """\
name = "real units"
[groups]
novice = 1
"""


def test_a_serial_sensors_table_is_read_and_kept() -> None:
    design = parse_design(f'{DESIGN}[sensors]\nsource = "serial"\nport = "/dev/ttyUSB2"\n')
    assert (design.sensors.source, design.sensors.port) == ("serial", "/dev/ttyUSB2")
    assert design.to_dict()["sensors"] == {"source": "serial", "port": "/dev/ttyUSB2"}
    assert StudyDesign.from_dict(design.to_dict()) == design
    # the source defaults to serial
    assert parse_design(f'{DESIGN}[sensors]\nport = "COM3"\n').sensors.source == "serial"


def test_an_lsl_sensors_table_is_read_and_kept() -> None:
    table = 'source = "lsl"\nstream = "name=\'FT\'"\nproximal_channel = 2\ndistal_channel = 0\n'
    design = parse_design(f"{DESIGN}[sensors]\n{table}")
    s = design.sensors
    assert (s.source, s.stream, s.proximal_channel, s.distal_channel) == ("lsl", "name='FT'", 2, 0)
    assert StudyDesign.from_dict(design.to_dict()) == design
    # channels 0 and 1 by default
    design = parse_design(f'{DESIGN}[sensors]\nsource = "lsl"\nstream = "type=\'Force\'"\n')
    assert (design.sensors.proximal_channel, design.sensors.distal_channel) == (0, 1)


def test_a_design_without_the_table_names_no_sensors() -> None:
    design = parse_design(DESIGN)
    assert design.sensors.source is None
    assert "sensors" not in design.to_dict()


LSL = 'source = "lsl"\nstream = "name=\'FT\'"\n'


@pytest.mark.parametrize(
    ("table", "said"),
    [
        ('source = "modbus"\nport = "x"', "sensors.source = 'modbus'; expected one of serial, lsl"),
        ('port = ""', "sensors.port = ''; expected the forces unit's serial port"),
        ("port = 3", "sensors.port = 3; expected"),
        ('source = "serial"', "sensors.port = None; expected"),
        ('port = "x"\nrate = 3', "unknown key sensors.rate for source 'serial'; expected one of"),
        ('source = "lsl"\nport = "x"', "unknown key sensors.port for source 'lsl'"),
        ('source = "lsl"', "sensors.stream = None; expected an LSL predicate"),
        ('source = "lsl"\nstream = "name=\'FT"', 'sensors.stream "name=\'FT" has'),
        (f"{LSL}proximal_channel = -1", "sensors.proximal_channel = -1; expected a channel"),
        (f"{LSL}distal_channel = true", "sensors.distal_channel = True; expected a channel"),
        (f"{LSL}distal_channel = 1.5", "sensors.distal_channel = 1.5; expected a channel"),
        (f"{LSL}proximal_channel = 1", "sensors.distal_channel = 1; expected a channel other"),
    ],
)
def test_a_bad_sensors_table_names_the_key_and_value(table: str, said: str) -> None:
    with pytest.raises(StudyInputError) as info:
        parse_design(f"{DESIGN}[sensors]\n{table}\n")
    assert said in str(info.value)
    assert "\n" not in str(info.value)
