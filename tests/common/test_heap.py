"""quadruped_common.heap: start-up objects leave the collector's reach, collection itself stays on."""
import gc
import weakref

import pytest

from quadruped_common.heap import frozen_startup_heap


@pytest.fixture
def unfrozen():
    yield
    gc.unfreeze()  # later tests in this process see an ordinary heap again


class Node:
    def __init__(self):
        self.me = self  # a reference cycle, as rospy's objects have


def test_objects_made_at_start_up_are_frozen(unfrozen):
    before = gc.get_freeze_count()
    with frozen_startup_heap():
        startup = [Node() for _ in range(5000)]
    assert gc.get_freeze_count() >= before + 5000
    assert gc.isenabled()
    del startup


def test_garbage_made_while_running_is_still_collected(unfrozen):
    with frozen_startup_heap():
        pass
    frozen = gc.get_freeze_count()
    cycles = [weakref.ref(Node()) for _ in range(1000)]  # unreachable cycles
    gc.collect()
    assert all(ref() is None for ref in cycles)
    assert gc.get_freeze_count() == frozen


def test_import_garbage_is_collected_before_freezing(unfrozen):
    gc.disable()
    try:
        cycles = [weakref.ref(Node()) for _ in range(1000)]  # cycles nobody collected yet
        with frozen_startup_heap():
            pass
        assert all(ref() is None for ref in cycles)  # freed, not frozen alive
    finally:
        gc.enable()


def test_start_up_that_raises_still_freezes(unfrozen):
    with pytest.raises(SystemExit):
        with frozen_startup_heap():
            raise SystemExit(1)
    assert gc.get_freeze_count() > 0
