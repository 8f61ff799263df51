"""The MQTT outbox: ordered, deduplicated, and kept on disk until each message is acknowledged."""

from __future__ import annotations

import threading

from bevflow_services.outbox import Outbox


def test_messages_come_out_in_order_once_and_survive_a_restart(tmp_path) -> None:
    path = tmp_path / "outbox.db"
    outbox = Outbox(path)
    assert outbox.add("t/a", b"1") and outbox.add("t/b", b"2") and outbox.add("t/a", b"3")
    assert not outbox.add("t/a", b"1")  # the bus delivered it twice
    first = outbox.next(timeout=0)
    assert (first.topic, first.payload) == ("t/a", b"1")
    outbox.mark_sent(first.seq)
    assert not outbox.add("t/a", b"1")  # still known once sent: a late duplicate is not sent again
    outbox.close()

    reopened = Outbox(path)
    assert reopened.backlog() == 2
    assert [reopened.next(0).payload for _ in range(1)] == [b"2"]  # unacknowledged: still first
    reopened.close()


def test_next_waits_for_a_message(tmp_path) -> None:
    outbox = Outbox(tmp_path / "outbox.db")
    assert outbox.next(timeout=0.05) is None
    threading.Timer(0.1, outbox.add, ("t", b"x")).start()
    message = outbox.next(timeout=10)
    assert message is not None and message.payload == b"x"
    outbox.close()


def test_sent_messages_are_forgotten_after_keep_s(tmp_path) -> None:
    outbox = Outbox(tmp_path / "outbox.db", keep_s=0)
    outbox.add("t", b"x")
    outbox.mark_sent(outbox.next(0).seq)
    outbox.mark_sent(-1)  # any later mark prunes
    assert outbox.add("t", b"x")  # forgotten, so new again
    outbox.close()
