"""A recorded sortie's MCAP data section carries its CRC (DataEnd), checked independently of
the writer: recomputed over the bytes, and by the mcap library's validating stream reader."""

from __future__ import annotations

import struct
import zlib

from mcap.records import DataEnd
from mcap.stream_reader import StreamReader

from groundstation.recording.writer import SortieRecorder
from groundstation.scenario import load_scenario
from groundstation.sim.simulation import Simulation

MAGIC_LEN = 8
DATA_END_LEN = 1 + 8 + 4  # opcode, record length, crc
FOOTER_LEN = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, summary offset start, crc


def test_the_data_section_crc_is_written_and_matches(tmp_path):
    rec = SortieRecorder(tmp_path)
    Simulation(load_scenario("static-ahead-20m"), keep_records=False, observers=[rec]).run()
    assert rec.closed and rec.error is None
    data = rec.path.read_bytes()
    footer = len(data) - MAGIC_LEN - FOOTER_LEN
    assert data[footer] == 0x02  # the Footer opcode
    (summary_start,) = struct.unpack_from("<Q", data, footer + 9)
    data_end = summary_start - DATA_END_LEN
    assert data[data_end] == 0x0F  # the DataEnd opcode
    (stored,) = struct.unpack_from("<I", data, data_end + 9)
    assert stored != 0 and stored == zlib.crc32(data[:data_end])  # from the magic on (spec)
    records = list(StreamReader(str(rec.path), validate_crcs=True).records)
    assert [r.data_section_crc for r in records if isinstance(r, DataEnd)] == [stored]
