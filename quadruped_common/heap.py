"""Keep Python's cyclic garbage collector out of the nodes' control periods.

A node imports rospy, numpy and scipy before it runs: 40,000-50,000 objects that live as long as the
process. CPython's full (generation-2) collection walks every one of them, and it runs whenever the
objects that survived younger collections reach a quarter of that heap. On this project's 2-core
development machine a full collection then took 20-35 ms in a driver or controller node and 55 ms in
sim_node (measured with ``gc.callbacks``; docs/sim_timing.md), longer than half the controller's 50 ms
stale-IMU limit, and it comes at an arbitrary point of a cycle.

``gc.freeze()`` (Python >= 3.7) moves every object tracked so far into a permanent generation that no
collection visits. Done once after start-up, a full collection walks only what the node has allocated
since, which in a steady loop is little. Collection itself stays on: reference cycles made while
running are still freed. :func:`quadruped_common.ros.node_startup.start_node` wraps every node's start-up
in :func:`frozen_startup_heap`.
"""
from __future__ import annotations

import contextlib
import gc
from typing import Iterator


@contextlib.contextmanager
def frozen_startup_heap() -> Iterator[None]:
    """Collect the import-time garbage on entry (no node thread runs yet, so the pause harms nothing),
    run the node's start-up (``rospy.init_node``, the node object), and freeze everything alive on
    exit. The objects made inside are frozen on exit too, also when start-up raises (the process then
    ends anyway)."""
    gc.collect()
    try:
        yield
    finally:
        gc.freeze()


__all__ = ["frozen_startup_heap"]
