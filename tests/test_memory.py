"""What a burst leaves in glibc's malloc arenas goes back to the system while ``sonibus run``
waits (``bus/memory.py``): the bus fuzz campaign's resident size had kept every arena's
high-water mark (80 MB free in them for 40 MB in use)."""

from __future__ import annotations

import ctypes
import threading

from sonibus.bus import Adapter, runner
from sonibus.bus.busconfig import BusConfig
from sonibus.bus.memory import GROWN, Trimmer, resident

from .conftest import free_port, wait_for

_libc = ctypes.CDLL(None)
_libc.malloc.restype, _libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
_libc.free.argtypes = [ctypes.c_void_p]
CHUNK, CHUNKS, KEEP_EVERY = 4000, 20_000, 50  # 80 MB in blocks below malloc's mmap threshold


def fragment(peak: list[int] | None = None) -> list[int]:
    """80 MB malloc'd on this thread's arena and written, then all freed but every
    ``KEEP_EVERY``-th block: the holes between them stay mapped (what a burst of messages
    leaves). The kept blocks, to free later; ``peak``: given the resident size once all
    is written, before the first free."""
    blocks = [_libc.malloc(CHUNK) for _ in range(CHUNKS)]
    for block in blocks:
        ctypes.memset(block, 1, CHUNK)
    if peak is not None:
        peak.append(resident())
    for i, block in enumerate(blocks):
        if i % KEEP_EVERY:
            _libc.free(block)
    return blocks[::KEEP_EVERY]


class Burst(Adapter):
    """A node whose worker allocates and frees like a flood of big messages, once."""

    kept: tuple[int, ...] = ()
    # the resident size at the burst's peak, before its frees (measured after them, a trim
    # may already have given back part of them: a full run saw 33 of the 50 MB fall after that)
    peak: int | None = None

    def _start(self) -> None:
        self.spawn(self._work, "burst")

    def _work(self) -> None:
        peak: list[int] = []
        self.kept = tuple(fragment(peak))
        self.peak = peak[0]
        self.stopping.wait()

    def _stop(self) -> None:
        for block in self.kept:
            _libc.free(block)


def test_what_a_burst_freed_goes_back_to_the_system_while_the_nodes_run():
    node, stop = Burst(name="burst"), threading.Event()
    cfg = BusConfig(multicast=False, listen=(f"tcp/127.0.0.1:{free_port()}",))
    thread = threading.Thread(target=runner.run, args=([node], cfg, stop), daemon=True)
    thread.start()
    try:
        wait_for(lambda: node.peak, 10, "the burst")
        wait_for(lambda: node.kept and resident() < node.peak - 50e6, 5, "the resident size to fall by 50 MB "
                 "of the 78 MB freed", lambda: f"{node.peak / 1e6:.0f} MB at the burst's peak, "
                                                f"{resident() / 1e6:.0f} MB now")
    finally:
        stop.set()
        thread.join(10)
    assert not thread.is_alive()


def test_no_trim_while_nothing_grew():
    trimmer = Trimmer(every_s=0.0, after_s=0.0)
    assert trimmer.active
    assert trimmer.check() is None and trimmer.trims == 0  # (a steady show: one read of /proc a second, no call)
    kept = fragment()
    try:
        released = trimmer.check()
        assert released is not None and released > 50e6, released
        assert trimmer.trims == 1 and trimmer.check() is None  # (once: the floor is what the trim left)
    finally:
        for block in kept:
            _libc.free(block)
    assert GROWN < 50e6
