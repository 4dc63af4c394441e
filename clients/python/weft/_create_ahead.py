"""Arrays created one step ahead: a small array created again with the same request (a
`wp.zeros(n, requires_grad=True)` in every step of a training loop: a loss, an output, a
temporary) is created once more through the fast lane right after, without waiting for the
reply, so the next creation of that kind takes it and costs no round trip.

Owns, per runtime: the requests seen lately (a request seen twice is created ahead from then
on) and at most SLOTS arrays created ahead, one per request. An array created ahead is what
the request asked for when it is taken: weftd zeroed it (init ZEROS) when it created it, in
order with the session's commands, and nothing else names it until it is handed out. Only
requests of at most MAX_BYTES (the gradient as much again), EMPTY or ZEROS, not pinned, with
no graph capture in progress; a creation refused for lack of memory first gives the arrays
held ahead back (weft.array._create). A creation ahead that fails is dropped quietly: the
next creation of that kind asks the daemon and gets the error itself.
"""
from __future__ import annotations

import collections

from . import _fast_lane

SLOTS = 8                 # arrays held ahead (each with its gradient, if any)
SEEN = 32                 # requests remembered
MAX_BYTES = 1 << 20       # the largest array created ahead
MAX_IN_FLIGHT = 4         # replies outstanding on the lane beyond which nothing is created ahead


class _Ahead:
    __slots__ = ("pending", "response")

    def __init__(self, pending):
        self.pending = pending        # the lane's PendingReply until collected
        self.response = None          # its CreateArrayResponse (None: the creation failed)

    def collected(self, reply) -> None:
        """The runtime's collection of the reply (in lane order): never the session's error."""
        try:
            self.response = reply.result()
        except Exception:  # noqa: BLE001 - a creation ahead that failed is only dropped
            self.response = None
        self.pending = None


class CreateAhead:
    """The arrays of one runtime created ahead (the runtime's lock guards every method)."""

    def __init__(self, rt):
        self.rt = rt
        self.slots: collections.OrderedDict = collections.OrderedDict()   # request -> _Ahead
        self.seen: collections.OrderedDict = collections.OrderedDict()    # request -> None

    def take(self, key: bytes):
        """The CreateArrayResponse of the array created ahead for request `key`, else None.
        Waits for its reply if it is not in yet (it was sent first)."""
        ahead = self.slots.pop(key, None)
        if ahead is None:
            return None
        if ahead.pending is not None:
            self.rt._collect_inflight()         # in lane order, up to and past this reply
        return ahead.response

    def created(self, key: bytes) -> None:
        """Request `key` was just created (by the daemon or from a slot): created ahead once
        more when it was seen before and the lane can carry it."""
        if key not in self.seen:
            self.seen[key] = None
            if len(self.seen) > SEEN:
                self.seen.popitem(last=False)
            return
        self.seen.move_to_end(key)
        if key in self.slots:
            return
        rt = self.rt
        lane = rt.fast_lane
        if lane is None or lane.broken or not rt.lane_arrays or \
                len(rt._inflight) >= MAX_IN_FLIGHT or \
                any(type(call) is not _fast_lane.PendingReply for call in rt._inflight):
            return
        try:
            pending = lane.send(_fast_lane.ARRAY_CREATE, key, _array_pb2().CreateArrayResponse)
        except Exception:  # noqa: BLE001 - the lane broke: the next call reports it
            return
        ahead = _Ahead(pending)
        pending.ahead = ahead
        rt._inflight.append(pending)
        self.slots[key] = ahead
        while len(self.slots) > SLOTS:
            self._give_back(self.slots.popitem(last=False)[1])

    def give_back_all(self) -> bool:
        """Frees every array held ahead (memory is short); whether there was any."""
        if not self.slots:
            return False
        while self.slots:
            self._give_back(self.slots.popitem(last=False)[1])
        return True

    def _give_back(self, ahead: _Ahead) -> None:
        if ahead.pending is not None:
            self.rt._collect_inflight()
        if ahead.response is not None:
            self.rt.free_later(ahead.response.info.handle)   # its gradient goes with it


def _array_pb2():
    from .v1 import array_pb2  # noqa: PLC0415

    return array_pb2
