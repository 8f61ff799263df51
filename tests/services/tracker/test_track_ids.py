from pathlib import Path

import pytest

from bevflow_services.tracker.track_ids import TrackIdError, TrackIdReservation


def test_a_restart_starts_past_every_id_the_previous_run_could_have_published(tmp_path: Path) -> None:
    path = tmp_path / "next-track-id"
    first = TrackIdReservation(path, block=10)
    assert first.first_id() == 1
    published = []
    next_id = 1
    for _ in range(25):  # three new tracks per tick, ids covered before they go out
        next_id += 3
        first.cover(next_id)
        published.extend(range(next_id - 3, next_id))
    # The process dies here without any goodbye; a new one reads only the file.
    restarted = TrackIdReservation(path, block=10).first_id()
    assert restarted > max(published)
    assert restarted - max(published) <= 10 + 1  # at most a block skipped


@pytest.mark.parametrize(
    "content, floor, expected",
    [
        (None, 1, 1),
        (None, 500, 500),
        ("1234\n", 1, 1234),
        ("1234", 5000, 5000),
    ],
)
def test_first_id_is_the_larger_of_the_file_and_the_floor(tmp_path: Path, content, floor, expected) -> None:
    path = tmp_path / "ids"
    if content is not None:
        path.write_text(content)
    reservation = TrackIdReservation(path, block=100)
    assert reservation.first_id(floor) == expected
    assert int(path.read_text()) == expected + 100


def test_cover_writes_only_when_a_block_is_used_up(tmp_path: Path) -> None:
    path = tmp_path / "ids"
    reservation = TrackIdReservation(path, block=100)
    reservation.first_id()
    path.write_text("sentinel")  # any write would replace it
    reservation.cover(101)
    assert path.read_text() == "sentinel"
    reservation.cover(102)
    assert int(path.read_text()) == 202


@pytest.mark.parametrize(
    "content, message",
    [
        ("twelve", "expected one whole number"),
        ("-4", "cannot be negative"),
    ],
)
def test_a_damaged_file_stops_the_tracker_with_the_path_in_the_message(tmp_path: Path, content, message) -> None:
    path = tmp_path / "ids"
    path.write_text(content)
    with pytest.raises(TrackIdError, match=message) as caught:
        TrackIdReservation(path).first_id()
    assert str(path) in str(caught.value)


def test_an_unwritable_place_is_reported(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(TrackIdError, match="cannot read the track id reservation: Not a directory"):
        TrackIdReservation(blocker / "ids").first_id()
