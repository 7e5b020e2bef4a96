"""``FrameRange``: the one value of ``--frames`` (bake, batch, render), parsed once."""

import pytest

from cloth_usd.core.frame_range import FrameRange, parse_frames, parse_time_codes
from cloth_usd.errors import ArgumentError


def test_frame_ranges():
    assert parse_frames("1:5:2").times().tolist() == [1.0, 3.0, 5.0]
    assert parse_frames("1001:1001").times().tolist() == [1001.0]
    assert FrameRange(0.0, 1.0, 0.25).times().tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]


def test_a_negative_step_says_step_must_be_positive():
    for text in ("1:5:-1", "1:5:0"):
        with pytest.raises(ArgumentError, match=rf"--frames '{text}': STEP must be positive"):
            parse_frames(text)
    assert FrameRange(1.0, 5.0, 2.0).count() == 3


def test_spec_and_str_read_back_as_the_same_range():
    r = FrameRange(1.0, 11.0, 2.0)
    assert (r.spec(), str(r)) == ("1:11:2", "1:11:2")
    assert (FrameRange(1001, 1096).spec(), str(FrameRange(1001, 1096))) == ("1001:1096", "1001:1096:1")
    for text in (r.spec(), str(r), "1001:1096", "0.5:2:0.25"):
        assert parse_frames(parse_frames(text).spec()) == parse_frames(text)


def test_chunks_cover_the_range_in_order():
    r = FrameRange(1.0, 11.0, 2.0)  # 1, 3, 5, 7, 9, 11
    parts = r.chunks(4)
    assert parts == [FrameRange(1.0, 7.0, 2.0), FrameRange(9.0, 11.0, 2.0)]
    assert [t for p in parts for t in p.times()] == r.times().tolist()
    assert FrameRange(1.0, 12.0, 5.0).chunks(2) == [FrameRange(1.0, 6.0, 5.0), FrameRange(11.0, 11.0, 5.0)]


@pytest.mark.parametrize("text, times", [
    ("1001,1030,1060", (1001.0, 1030.0, 1060.0)),
    ("1001:1096:24", (1001.0, 1025.0, 1049.0, 1073.0)),
    ("1001:1003,1050", (1001.0, 1002.0, 1003.0, 1050.0)),
    ("7", (7.0,)),
])
def test_time_codes_are_a_list_of_codes_and_ranges(text, times):
    assert parse_time_codes(text) == times


@pytest.mark.parametrize("text, message", [
    ("1001,abc", "'abc' is not a time code"),
    ("1001,", "'' is not a time code"),
    ("1010:1001", "--frames '1010:1001': empty range"),
])
def test_bad_time_codes_name_the_item(text, message):
    with pytest.raises(ArgumentError, match=message):
        parse_time_codes(text)
