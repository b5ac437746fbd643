"""frozen_heap: the heap alive before a real-time block is out of the collector's reach."""

from __future__ import annotations

import gc

from maglev_ros.frozen_heap import frozen_heap


def test_a_collection_inside_traverses_only_what_the_block_allocated():
    before = [[i] for i in range(20_000)]  # tracked containers alive before the block
    with frozen_heap() as frozen:
        assert frozen > 20_000 and gc.get_freeze_count() > 20_000
        made = [[i] for i in range(500)]
        assert len(gc.get_objects()) < 2_000  # the block's own objects, not the heap
        assert gc.isenabled()  # cycles made meanwhile are still freed
    assert gc.get_freeze_count() == 0
    assert len(gc.get_objects()) > 20_000  # everything is traversed again
    del before, made


def test_nested_blocks_leave_the_heap_frozen_until_the_outermost_ends():
    with frozen_heap():
        with frozen_heap():
            pass
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0
