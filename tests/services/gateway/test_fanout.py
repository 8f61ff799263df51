from __future__ import annotations

import asyncio
import threading

import pytest

from bevflow_services.gateway.fanout import Broadcaster, Subscription, pump


def test_a_stuck_subscriber_drops_its_oldest_items_while_another_receives_everything() -> None:
    async def scenario() -> tuple[list[int], list[int], int, list[int]]:
        broadcaster: Broadcaster[int] = Broadcaster(maxsize=4)
        fast_got: list[int] = []
        stuck_got: list[int] = []
        release = asyncio.Event()

        async def fast_send(item: int) -> None:
            fast_got.append(item)

        async def stuck_send(item: int) -> None:
            stuck_got.append(item)
            await release.wait()  # a client whose socket never drains

        async with broadcaster.subscribe(maxsize=200) as fast, broadcaster.subscribe() as stuck:
            tasks = [asyncio.create_task(pump(fast, fast_send)), asyncio.create_task(pump(stuck, stuck_send))]
            for i in range(100):
                broadcaster.publish(i)  # never waits, even though ``stuck`` is full
            for _ in range(20):
                await asyncio.sleep(0)
            left_in_queue = [stuck.queue.get_nowait() for _ in range(stuck.queue.qsize())]
            dropped = stuck.dropped
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
        return fast_got, stuck_got, dropped, left_in_queue

    fast_got, stuck_got, dropped, left = asyncio.run(scenario())
    assert fast_got == list(range(100))
    # The stuck client kept only the newest 4 items; it is blocked sending the first of them.
    assert dropped == 96
    assert stuck_got == [96]
    assert left == [97, 98, 99]


def test_publish_from_another_thread_reaches_the_subscribers_loop() -> None:
    async def scenario() -> list[str]:
        broadcaster: Broadcaster[str] = Broadcaster()
        async with broadcaster.subscribe() as sub:
            thread = threading.Thread(target=lambda: [broadcaster.publish(s) for s in ("a", "b", "c")])
            thread.start()
            got = [await asyncio.wait_for(sub.get(), 5.0) for _ in range(3)]
            thread.join()
        return got

    assert asyncio.run(scenario()) == ["a", "b", "c"]


def test_a_subscriber_only_receives_what_its_filter_accepts() -> None:
    async def scenario() -> list[int]:
        broadcaster: Broadcaster[int] = Broadcaster()
        async with broadcaster.subscribe(accept=lambda i: i % 2 == 0) as sub:
            for i in range(6):
                broadcaster.publish(i)
            return [sub.queue.get_nowait() for _ in range(sub.queue.qsize())]

    assert asyncio.run(scenario()) == [0, 2, 4]


def test_leaving_the_block_unsubscribes() -> None:
    async def scenario() -> tuple[int, int]:
        broadcaster: Broadcaster[int] = Broadcaster()
        async with broadcaster.subscribe():
            inside = len(broadcaster)
        broadcaster.publish(1)  # nobody left to receive it; must not fail
        return inside, len(broadcaster)

    assert asyncio.run(scenario()) == (1, 0)


def test_queue_size_must_be_positive() -> None:
    async def scenario() -> None:
        Subscription(0)

    with pytest.raises(ValueError, match="maxsize"):
        asyncio.run(scenario())
