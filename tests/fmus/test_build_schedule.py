"""The first build's schedule (fmu_models/export/build.py): a freed
compiler slot goes to the largest compile waiting, so the longest compiles
start first and no core idles at the end while one compiles alone."""
from __future__ import annotations

import threading
import time

from fmu_models.export import build


def test_a_free_compiler_slot_goes_to_the_largest_compile_waiting():
    slots, order = build._CompilerSlots(1), []
    waiting = threading.Barrier(4)

    def compile_(cost):
        waiting.wait()
        time.sleep(0.05 * cost)  # arrive in the order 1, 2, 3 (smallest first), all while the slot is taken
        with slots.held(cost):
            order.append(cost)

    with slots.held(0):  # the slot taken until the three are waiting for it
        threads = [threading.Thread(target=compile_, args=(cost,)) for cost in (1, 2, 3)]
        for thread in threads:
            thread.start()
        waiting.wait()
        while len(slots._waiting) < 3:
            time.sleep(0.01)
    for thread in threads:
        thread.join()
    assert order == [3, 2, 1]
