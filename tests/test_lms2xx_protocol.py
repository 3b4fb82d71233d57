"""LMS2xx protocol layer: every vector of docs/lms2xx.md, the real capture, B0 decoding, the parser."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.lms2xx import protocol as P
from datmo_cli.lms2xx.frame_parser import FrameParser

pytestmark = pytest.mark.unit

# (bytes, payload builder or None) for every telegram in the doc's CRC table (§3)
VECTORS = {
    "status": ("02 00 01 00 31 15 12", P.cmd_status),
    "continuous": ("02 00 02 00 20 24 34 08", P.cmd_stream),
    "stop": ("02 00 02 00 20 25 35 08", P.cmd_stop),
    "installation": ("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5", P.cmd_installation),
    "38400": ("02 00 02 00 20 40 50 08", lambda: P.cmd_baud(38400)),
    "19200": ("02 00 02 00 20 41 51 08", lambda: P.cmd_baud(19200)),
    "9600": ("02 00 02 00 20 42 52 08", lambda: P.cmd_baud(9600)),
    "500k": ("02 00 02 00 20 48 58 08", lambda: P.cmd_baud(500000)),
    "one scan": ("02 00 02 00 30 01 31 18", P.cmd_one_scan),
    "variant 180/0.5": ("02 00 05 00 3B B4 00 32 00 3B 1F", lambda: P.cmd_variant(180, 50)),
    "variant 180/1": ("02 00 05 00 3B B4 00 64 00 97 49", lambda: P.cmd_variant(180, 100)),
    "variant 100/1": ("02 00 05 00 3B 64 00 64 00 1D 0F", lambda: P.cmd_variant(100, 100)),
    "variant 100/0.5": ("02 00 05 00 3B 64 00 32 00 B1 59", lambda: P.cmd_variant(100, 50)),
    "variant 100/0.25": ("02 00 05 00 3B 64 00 19 00 E7 72", lambda: P.cmd_variant(100, 25)),
    "read config": ("02 00 01 00 74 50 12", P.cmd_read_config),
    "reset 10h": ("02 00 01 00 10 34 12", lambda: P.host_frame(b"\x10")),
    "type 3Ah": ("02 00 01 00 3A 1E 12", lambda: P.host_frame(b"\x3a")),
    "reply A0": ("02 80 03 00 A0 00 10 16 0A", lambda: P.reply_frame(b"\xa0\x00", 0x10)),
    "reply BB": ("02 80 07 00 BB 01 B4 00 32 00 10 03 9D", lambda: P.reply_frame(bytes.fromhex("BB01B4003200"))),
    "reply 92h": ("02 80 02 00 92 10 7F 33", lambda: P.reply_frame(b"\x92")),
}


@pytest.mark.parametrize("name", list(VECTORS))
def test_doc_vectors_build_parse_and_crc(name):
    text, build = VECTORS[name]
    raw = bytes.fromhex(text)
    assert build() == raw
    frame = P.parse_frame(raw)
    assert P.crc16(raw[:-2]) == raw[-2] | (raw[-1] << 8)
    assert P.build_frame(frame.payload, address=frame.address, status=frame.status) == raw
    assert frame.is_reply == (raw[1] == 0x80)


def test_crc_is_not_crc16_arc():
    assert P.crc16(bytes.fromhex("0200010031")) == 0x1215


def test_manual_errata_are_rejected():
    # TL T6-4 prints the installation telegram with the CRC of a mistyped password
    with pytest.raises(P.ProtocolError, match="CRC"):
        P.parse_frame(bytes.fromhex("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 5F B2"))


def test_reply_codes_and_status_fields():
    frame = P.parse_frame(bytes.fromhex("02 80 07 00 BB 01 B4 00 32 00 10 03 9D"))
    assert (frame.command, frame.data, frame.status) == (0xBB, bytes.fromhex("01B4003200"), 0x10)
    host = P.parse_frame(P.cmd_status())
    assert host.status is None and host.data == b""


def test_real_capture():
    raw = shared_path("lms2xx", "lms2xx_b0_361_mm.bin").read_bytes()
    assert len(raw) == 732 and raw[:5] == bytes.fromhex("0280D602B0")
    frame = P.parse_frame(raw)
    assert P.crc16(raw[:-2]) == 0x4764
    tel = P.decode_b0(frame.data, frame.status)
    assert (tel.count, tel.units, tel.status, tel.partial, tel.offset) == (361, "mm", 0x10, False, 0)
    assert tel.scan_index is None
    dist, flags = P.split_values(tel.values, 0)
    assert dist.min() == 407
    assert (flags != 0).any()  # e.g. 0x232F: field A bit set, distance 0x32F
    ranges = P.values_to_ranges(tel.values, tel.units, 0)
    assert ranges.dtype == np.float32 and np.isfinite(ranges).all()
    assert ranges.min() == np.float32(0.407) and ranges.max() < 8.0
    # the incremental parser finds it in any chunking, after garbage
    parser = FrameParser()
    stream = b"\x11\x22\x02\x33" + raw + raw[:100]
    got = [f for i in range(0, len(stream), 37) for f in parser.feed(stream[i : i + 37])]
    assert [f.raw for f in got] == [raw] and parser.stats.resyncs == 1 and parser.stats.discarded == 4


@pytest.mark.parametrize("variant", list(P.VARIANTS))
@pytest.mark.parametrize("units", ["mm", "cm"])
@pytest.mark.parametrize("indices", [None, (17, 200)])
def test_b0_every_variant_round_trip(variant, units, indices):
    n = P.VARIANTS[variant]
    values = np.random.default_rng(n).integers(0, 0x1FF7, n).astype(np.uint16)
    payload = P.encode_b0(values, units, indices=indices)
    raw = P.reply_frame(payload)
    assert len(raw) == {181: 372, 361: 732, 101: 212, 201: 412, 401: 812}[n] + (2 if indices else 0)
    assert raw[2] | (raw[3] << 8) == P.b0_length(n, indices is not None)
    frame = P.parse_frame(raw)
    tel = P.decode_b0(frame.data, frame.status)
    assert np.array_equal(tel.values, values) and tel.units == units
    assert (tel.scan_index, tel.telegram_index) == (indices or (None, None))
    unit = 0.001 if units == "mm" else 0.01
    assert np.array_equal(P.values_to_ranges(values, units), (values * unit).astype(np.float32))


def test_info_word_examples_and_partial_bits():
    assert P.decode_b0(bytes.fromhex("6941") + bytes(722)).units == "mm"
    assert P.decode_b0(bytes.fromhex("6901") + bytes(722)).units == "cm"
    for offset in range(4):
        payload = P.encode_b0(np.zeros(180, np.uint16), partial=True, offset=offset)
        info = payload[1] | (payload[2] << 8)
        assert info & 0x3FF == 180 and info >> 13 & 1 == 1 and (info >> 11) & 3 == offset
        tel = P.decode_b0(payload[1:])
        assert tel.partial and tel.offset == offset
    with pytest.raises(P.ProtocolError, match="361 values"):
        P.decode_b0(bytes.fromhex("6941") + bytes(700))


@pytest.mark.parametrize("angle, res", [(180, 50), (100, 50), (100, 25), (180, 100)])
def test_partial_scans_tile_the_complete_scan(angle, res):
    n = P.VARIANTS[(angle, res)]
    positions = np.concatenate([P.partial_positions(angle, res, o) for o in P.partial_offsets(res)])
    assert np.array_equal(np.sort(positions), np.arange(n))
    # the x.00° partial carries one value more than the others
    counts = [P.partial_count(angle, res, o) for o in P.partial_offsets(res)]
    assert counts[0] == angle + 1 and all(c == angle for c in counts[1:])


@pytest.mark.parametrize("mode, bits", [(0, 13), (1, 13), (2, 13), (3, 14), (4, 14), (5, 15), (6, 15)])
def test_measuring_modes_distance_and_flags(mode, bits):
    flag = 1 << bits
    values = np.array([100 | flag, 2000, (1 << bits) - 10], np.uint16)
    dist, flags = P.split_values(values, mode)
    assert list(dist) == [100, 2000, (1 << bits) - 10]
    assert list(flags) == [1, 0, 0]
    top = (1 << bits) - 1
    codes = np.array([top, top - 1, top - 2, top - 4, top - 5, top - 8, top - 9], np.uint16) | np.uint16(flag)
    r = P.values_to_ranges(codes, "mm", mode)
    assert np.isnan(r[:5]).all()  # invalid, dazzle, overflow, SNR, channel error
    assert r[5] == np.inf  # greater than maximum (...F7)
    assert r[6] == np.float32((top - 9) * 0.001)  # the largest valid value
    assert P.range_max_m(mode, "mm") == {13: 8.0, 14: 16.0, 15: 32.0}[bits]


def test_ranges_values_round_trip_and_codes():
    r = np.array([0.0, 1.234, np.inf, np.nan, 9.0], np.float32)
    v = P.ranges_to_values(r, "mm", 0)
    assert list(v) == [0, 1234, 0x1FF7, 0x1FFF, 0x1FF7]
    back = P.values_to_ranges(v, "mm", 0)
    assert back[1] == np.float32(1.234) and back[2] == np.inf and np.isnan(back[3]) and back[4] == np.inf
    with pytest.raises(P.ProtocolError):
        P.distance_bits(0x3F)


def test_status_and_config_blocks():
    block = P.build_status(measuring_mode=3, angle_deg=100, resolution_cdeg=25, baud=500000, units="cm")
    assert len(block) == P.STATUS_BYTES
    s = P.parse_status(block)
    assert (s.measuring_mode, s.angle_deg, s.resolution_cdeg, s.baud, s.units) == (3, 100, 25, 500000, "cm")
    assert P.parse_frame(P.reply_frame(b"\xb1" + block)).raw[2:4] == (154).to_bytes(2, "little")
    assert len(P.reply_frame(b"\xb1" + block)) == 160
    conf = P.parse_config(P.DEFAULT_CONFIG)
    assert (conf.units, conf.indices, conf.measuring_mode) == ("mm", False, 0)
    changed = P.with_config(P.DEFAULT_CONFIG, units="cm", indices=True)
    assert P.parse_config(changed).units == "cm" and P.parse_config(changed).indices
    assert [i for i in range(P.CONFIG_BYTES) if changed[i] != P.DEFAULT_CONFIG[i]] == [4, 6]


def test_rates_follow_the_table():
    assert P.telegram_rate_hz(50, 500000) == pytest.approx(37.5, rel=2e-3)
    assert P.telegram_rate_hz(50, 9600) == pytest.approx(1.25, rel=1e-2)
    assert P.telegram_rate_hz(100, 38400) == pytest.approx(8.3, rel=1e-2)
    assert P.telegram_rate_hz(25, 19200) == pytest.approx(2.1, rel=1e-2)


def test_parser_counts_crc_and_length_errors_and_handshake():
    good = P.reply_frame(b"\xa0\x00")
    bad_crc = good[:-1] + bytes([good[-1] ^ 0xFF])
    scan = P.reply_frame(P.encode_b0(np.arange(181, dtype=np.uint16)))
    bad_len = scan[:2] + (2 * 181 + 8).to_bytes(2, "little") + scan[4:]  # length disagrees with the info word
    parser = FrameParser()
    items = parser.feed(bytes([P.ACK]) + bad_crc + good + bad_len + scan + bytes([P.NAK]))
    assert items[0] == P.ACK and items[-1] == P.NAK
    frames = [i for i in items if isinstance(i, P.Frame)]
    assert [f.command for f in frames] == [0xA0, 0xB0]
    assert parser.stats.crc_errors == 1 and parser.stats.length_errors == 1
    host = FrameParser(replies=False)
    assert [f.command for f in host.feed(P.cmd_status() + b"\x02\x00\x01\x00\x31\x00\x00" + P.cmd_stop())] == [
        0x31,
        0x20,
    ]
    assert host.stats.crc_errors == 1


# ------------------------------------------------------------------------------------------ properties

payloads = st.binary(min_size=1, max_size=120)


@given(payload=payloads, status=st.integers(0, 255), reply=st.booleans())
def test_build_parse_round_trip(payload, status, reply):
    raw = P.reply_frame(payload, status) if reply else P.host_frame(payload)
    f = P.parse_frame(raw)
    assert f.payload == payload and f.status == (status if reply else None)


frames_st = st.lists(
    st.one_of(
        st.builds(
            lambda n, seed: P.reply_frame(
                P.encode_b0(np.random.default_rng(seed).integers(0, 0xFFFF, n).astype(np.uint16))
            ),
            st.integers(0, 401),
            st.integers(0, 1000),
        ),
        st.builds(
            lambda code, data: P.reply_frame(bytes([code]) + data),
            st.sampled_from([0xA0, 0xB1, 0xBB, 0xF4, 0xF7, 0x92]),
            st.binary(max_size=60),
        ),
    ),
    min_size=1,
    max_size=8,
)


@settings(max_examples=150, deadline=None)
@given(
    frames=frames_st,
    garbage=st.lists(st.binary(max_size=40), min_size=9, max_size=9),
    cuts=st.lists(st.integers(1, 300), max_size=40),
)
def test_parser_recovers_every_frame_from_any_chunking(frames, garbage, cuts):
    stream = b"".join(g + f for g, f in zip(garbage, frames + [b""], strict=False)) + garbage[-1]
    parser = FrameParser()
    got, pos = [], 0
    for c in cuts:
        got += parser.feed(stream[pos : pos + c])
        pos += c
    got += parser.feed(stream[pos:])
    assert [f.raw for f in got if isinstance(f, P.Frame)] == frames
    one = FrameParser()
    assert [f.raw for f in one.feed(stream) if isinstance(f, P.Frame)] == frames
    assert one.stats == parser.stats  # counts do not depend on the chunking


def test_parser_says_how_many_bytes_a_started_frame_still_needs():
    frame = P.reply_frame(P.encode_b0(np.arange(361, dtype=np.uint16)))
    parser = FrameParser(replies=True)
    assert parser.needed == 0
    parser.feed(b"\x11" + frame[:3])  # garbage, then too little of a header to read its length
    assert parser.needed == 0
    parser.feed(frame[3:100])
    assert parser.needed == len(frame) - 100
    assert len(parser.feed(frame[100:])) == 1 and parser.needed == 0
