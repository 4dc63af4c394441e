"""The fast lane: ExecService.Submit and Synchronize, ArrayService.Create, Free and Describe of
this process's session over a Unix SOCK_SEQPACKET socket, without gRPC (docs/protocol.md
"Fast lane"; the daemon's side is server/fast_lane.h).

The daemon names the socket and a one-time secret in the OpenSessionResponse of a local
client; `FastLane.connect` binds one connection to the session with them. Frames are one
datagram each: a request is a little-endian u32 method (1 hello, 2 Submit, 3 Synchronize,
4 Create, 5 Free, 6 Describe) then the serialized request message; a reply is a u32 status
code (gRPC numbering), u32 flags (bit 0: more frames follow; bit 1: the daemon ends the
connection after it), then a piece of the payload (the serialized response, or the error
message). Calls on one FastLane must not overlap (the Runtime's lock orders them).
WEFT_FAST_LANE=0 turns it off.

Where the daemon offers it (hello capability "ring"), the connection then moves onto a
shared-memory ring (_Ring; the daemon's side is server/lane_ring.h): the same frames as records
in a memory region both processes map, each side polling for the other's records a short
while and otherwise sleeping on the socket until a wake frame comes. WEFT_LANE_RING=0 keeps the
socket.
"""
from __future__ import annotations

import ctypes
import os
import platform
import select
import socket
import struct
import time

import grpc

from .errors import WeftError

HELLO, SUBMIT, SYNCHRONIZE = 1, 2, 3
ARRAY_CREATE, ARRAY_FREE, ARRAY_DESCRIBE, ARRAY_IMPORT_CUDA = 4, 5, 6, 7
GEOMETRY_CALL = 8
# A Submit the daemon answers only when it fails (its error reply has QUIET_REPLY_FLAG): the
# asynchronous batches, where the client never waited for more than "queued". Used when the
# hello's reply lists "quiet-submit" (WEFT_QUIET_SUBMIT=0: never).
SUBMIT_QUIET = 9
QUIET_REPLY_FLAG = 4
# A Free the daemon never answers (FreeArrayRequest.handles): the arrays this process released,
# sent without waiting (a handle already gone is what was asked for). Used when the hello's
# reply lists "unanswered-free".
ARRAY_FREE_UNANSWERED = 10
FREE_HANDLES_PER_FRAME = 4096    # 11 bytes each at most: far inside MAX_REQUEST_BYTES
# Frames sent before their replies are read by call_many: the replies wait in this process's
# receive buffer meanwhile, and a window this small never fills it (the daemon would block).
PIPELINE_WINDOW = 32
# Requests larger than this go through gRPC (the daemon refuses frames over 160 KiB; a datagram
# must also fit the socket's send buffer).
MAX_REQUEST_BYTES = 128 << 10
# The largest reply accepted (the gRPC path's limit on a message).
MAX_REPLY_BYTES = 64 << 20
_RECV_BYTES = (64 << 10) + 8
# A synchronizing call polls for its reply this long before blocking in recv: a short
# launch + synchronize is answered within tens of microseconds, less than a thread wake-up
# costs on a virtual machine. Only where there are cores to spare (4 or more);
# WEFT_FAST_LANE_SPIN_US sets it (0: never poll).
SPIN_S = float(os.environ.get("WEFT_FAST_LANE_SPIN_US",
                              "100" if (os.cpu_count() or 1) >= 4 else "0")) * 1e-6
# A synchronize that waits for GPU work polls longer: its reply comes when the GPU is done,
# and CUDA's own synchronize (what a Warp program waits in) spins the same way while the
# process has fewer contexts than cores. WEFT_FAST_LANE_GPU_SPIN_US sets it (0: as SPIN_S).
SPIN_GPU_S = float(os.environ.get("WEFT_FAST_LANE_GPU_SPIN_US",
                                  "20000" if (os.cpu_count() or 1) >= 4 else "0")) * 1e-6

RING_OPEN, RING_WAKE = 11, 12
WAKE_REPLY_FLAG = 8

_CODE_NAMES = {code.value[0]: code.name for code in grpc.StatusCode}
_METHOD_HEADERS = {method: struct.pack("<I", method) for method in range(1, 13)}


def enabled() -> bool:
    return os.environ.get("WEFT_FAST_LANE", "1") != "0"


class FastLaneError(WeftError):
    """The connection failed (not a daemon error about the request): the caller may fall back
    to gRPC for calls not yet sent."""

_MEMBARRIER_CMD_GLOBAL_EXPEDITED = 1 << 1
_MEMBARRIER_CMD_REGISTER_GLOBAL_EXPEDITED = 1 << 2
_SYS_MEMBARRIER = 324          # x86-64
_membarrier = None             # libc's syscall(SYS_membarrier, ...), once registered


def _ring_barrier_ready() -> bool:
    """Registers this process for the daemon's membarrier(GLOBAL_EXPEDITED), which orders a
    record this process published against the daemon's sleep flag (server/lane_ring.h). Only on
    x86-64 Linux, whose stores become visible in program order (a record before its head)."""
    global _membarrier
    if _membarrier is not None:
        return True
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        return False
    try:
        syscall = ctypes.CDLL(None, use_errno=True).syscall
        syscall.restype = ctypes.c_long
        if syscall(_SYS_MEMBARRIER, _MEMBARRIER_CMD_REGISTER_GLOBAL_EXPEDITED, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    _membarrier = syscall
    return True


_NATIVE_RING = False           # weft._lane_ring once looked up (None: absent or turned off)


def _native_ring():
    """weft._lane_ring (clients/python/native/lane_ring.c: put, take), or None when it was not
    built or WEFT_NATIVE_LANE=0 turns it off (records are then written and read in Python)."""
    global _NATIVE_RING
    if _NATIVE_RING is False:
        from . import _native  # noqa: PLC0415

        _NATIVE_RING = _native.optional("_lane_ring", "WEFT_NATIVE_LANE")
    return _NATIVE_RING


class _Ring:
    """This process's side of a lane's ring (layout: server/lane_ring.h): request records are
    written here and published by the request head, reply records taken and released by the
    reply tail; the flags say who sleeps on the socket."""

    MAGIC, VERSION = 0x47524657, 1
    REQUEST_HEAD, REQUEST_TAIL, DAEMON_ASLEEP = 64, 128, 192
    REPLY_HEAD, REPLY_TAIL, CLIENT_ASLEEP = 256, 320, 384
    WRAP = 0xFFFFFFFF
    # A writer that finds the request area full waits this long between looks once a short
    # spin found no room (the daemon takes records as fast as it serves them).
    FULL_WAIT_S = 50e-6

    def __init__(self, fd: int, size: int, sock: socket.socket):
        import mmap
        self._mm = mmap.mmap(fd, size)
        self._mv = memoryview(self._mm)
        # The control words read and written whole (one 8- or 4-byte access each: the daemon
        # must never see half of a head; struct's little-endian codes go byte by byte).
        self._u64 = self._mv.cast("Q")
        self._u32 = self._mv.cast("I")
        self._sock = sock
        magic, version, self._req_cap, self._rep_cap, self._req_base, self._rep_base = \
            struct.unpack_from("<6I", self._mm, 0)
        if magic != self.MAGIC or version != self.VERSION or \
                self._rep_base + self._rep_cap > size or self._req_base + self._req_cap > size:
            self.close()
            raise FastLaneError("fast lane: the daemon's ring has an unknown layout", "UNAVAILABLE")
        self._req_head = self._u64[self.REQUEST_HEAD // 8]
        self._req_tail = 0           # the daemon's tail, as last read
        self._rep_tail = self._u64[self.REPLY_TAIL // 8]
        self.wakes_sent = 0          # wake frames this process had to send (the daemon slept)
        # weft._lane_ring writes request records and reads reply records in C at the mapping's
        # address (held by _anchor, released before the mapping closes); None: in Python
        self._size = size
        self._anchor = None
        self._native_put = self._native_take = None
        native = _native_ring()
        if native is not None:
            self._anchor = ctypes.c_char.from_buffer(self._mm)
            self._address = ctypes.addressof(self._anchor)
            self._native_put, self._native_take = native.put, native.take

    def close(self) -> None:
        self._native_put = self._native_take = None
        self._anchor = None           # the export the C writer's address came from
        try:
            self._u64.release()
            self._u32.release()
            self._mv.release()
            self._mm.close()
        except (BufferError, ValueError):
            pass

    def put(self, header: bytes, body: bytes) -> None:
        """Writes one request frame (header + body) as a record and publishes it; wakes the
        daemon when it sleeps. In C (weft._lane_ring) where it was built, unless the request
        area lacks room by the tail last read (then here: the tail is read again, waiting)."""
        native = self._native_put
        if native is not None:
            head = native(self._address, self._size, self._req_cap, self._req_base, self._req_head,
                          self._req_tail, header, body)
            if head >= 0:
                self._req_head = head
                if self._u32[self.DAEMON_ASLEEP >> 2]:
                    self.wakes_sent += 1
                    self._sock.send(_METHOD_HEADERS[RING_WAKE])
                return
        mm, cap, u32 = self._mm, self._req_cap, self._u32
        n = len(header) + len(body)
        rec = (4 + n + 7) & ~7
        head = self._req_head
        pos = head % cap
        contiguous = cap - pos
        need = rec if rec <= contiguous else contiguous + rec
        if cap - (head - self._req_tail) < need:
            self._wait_for_room(head, need)
        base = self._req_base
        if rec > contiguous:
            u32[(base + pos) >> 2] = self.WRAP
            head += contiguous
            pos = 0
        at = base + pos + 4
        u32[(at - 4) >> 2] = n
        mm[at:at + len(header)] = header
        mm[at + len(header):at + n] = body
        head += rec
        self._u64[self.REQUEST_HEAD >> 3] = head
        self._req_head = head
        if u32[self.DAEMON_ASLEEP >> 2]:
            self.wakes_sent += 1
            self._sock.send(_METHOD_HEADERS[RING_WAKE])

    def daemon_polls(self) -> bool:
        """Whether weftd polls the ring now (its sleep flag is clear)."""
        return not self._u32[self.DAEMON_ASLEEP >> 2]

    def _wait_for_room(self, head: int, need: int) -> None:
        cap, u64 = self._req_cap, self._u64
        spins = 0
        poller = None
        while True:
            self._req_tail = u64[self.REQUEST_TAIL >> 3]
            if cap - (head - self._req_tail) >= need:
                return
            spins += 1
            if spins < 64:
                continue
            if poller is None:
                poller = select.poll()
                poller.register(self._sock, 0)
            if any(ev & (select.POLLHUP | select.POLLERR | select.POLLNVAL)
                   for _, ev in poller.poll(self.FULL_WAIT_S * 1e3)):
                raise FastLaneError("weftd closed the fast lane", "UNAVAILABLE")

    def take_into(self, out_address: int, out_len: int, spin_s: float = 0.0) -> int:
        """The next reply record's frame copied to `out_address` (a buffer of `out_len` bytes the
        caller keeps alive), polling up to `spin_s` for one: its length, or -1 when none came.
        In C (weft._lane_ring.take): only where it was built (`_native_take`; else take())."""
        try:
            got = self._native_take(self._address, self._size, self._rep_cap, self._rep_base, self._rep_tail,
                         out_address, out_len, int(spin_s * 1e9))
        except ValueError as err:
            raise FastLaneError(f"fast lane: {err}", "UNAVAILABLE") from None
        if got == -1:
            return -1
        n, self._rep_tail = got
        return n

    def take(self, view) -> int:
        """The next reply record copied into `view`: its length, or -1 when none is in."""
        tail = self._rep_tail
        if self._u64[self.REPLY_HEAD >> 3] == tail:
            return -1
        cap, base, u32 = self._rep_cap, self._rep_base, self._u32
        pos = tail % cap
        n = u32[(base + pos) >> 2]
        if n == self.WRAP:
            tail += cap - pos
            pos = 0
            n = u32[base >> 2]
        if n > len(view):
            raise FastLaneError("fast lane: a ring record larger than a reply frame", "UNAVAILABLE")
        at = base + pos + 4
        view[:n] = self._mv[at:at + n]
        tail += (4 + n + 7) & ~7
        self._u64[self.REPLY_TAIL >> 3] = tail
        self._rep_tail = tail
        return n

    def wait(self, view) -> int:
        """The next reply record, sleeping on the socket until the daemon wakes this process:
        its length, or 0 when the daemon closed the lane."""
        u32 = self._u32
        while True:
            n = self.take(view)
            if n >= 0:
                return n
            u32[self.CLIENT_ASLEEP >> 2] = 1
            try:
                _membarrier(_SYS_MEMBARRIER, _MEMBARRIER_CMD_GLOBAL_EXPEDITED, 0)   # flag, then look
                n = self.take(view)
                if n >= 0:
                    return n
                frame = self._sock.recv(64)
            finally:
                u32[self.CLIENT_ASLEEP >> 2] = 0
            if not frame:
                return 0
            if len(frame) != 8 or not struct.unpack_from("<I", frame, 4)[0] & WAKE_REPLY_FLAG:
                raise FastLaneError("fast lane: a reply on the socket of a ring", "UNAVAILABLE")


class FastLane:
    def __init__(self, sock: socket.socket):
        self._sock = sock
        self.broken = False
        self.quiet = False            # the daemon answers SUBMIT_QUIET only when it fails
        self.quiet_error = None       # the first failure of a quiet Submit not yet taken
        self.unanswered_free = False  # the daemon serves ARRAY_FREE_UNANSWERED
        self._buf = bytearray(_RECV_BYTES)      # every reply frame is received into this
        self._view = memoryview(self._buf)
        # where weft._lane_ring.take copies a ring's reply frames (the export keeps the
        # bytearray from being resized while the address is in use)
        self._buf_anchor = ctypes.c_char.from_buffer(self._buf)
        self._buf_address = ctypes.addressof(self._buf_anchor)
        self.ring = None              # the shared-memory ring, once open (_Ring)

    @classmethod
    def connect(cls, path: str, session_id: str, secret: bytes, hello_pb) -> "FastLane":
        """Connects and sends the hello; raises WeftError when the daemon refuses it."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            sock.settimeout(10.0)
            sock.connect(path)
            sock.settimeout(None)
            lane = cls(sock)
            offered = lane._call(HELLO, hello_pb(session_id=session_id, secret=secret).SerializeToString())
            lane.quiet = b"quiet-submit" in offered.split() and \
                os.environ.get("WEFT_QUIET_SUBMIT", "1") != "0"
            lane.unanswered_free = b"unanswered-free" in offered.split()
            if b"ring" in offered.split() and os.environ.get("WEFT_LANE_RING", "1") != "0" and \
                    _ring_barrier_ready():
                lane._open_ring()
            return lane
        except BaseException:
            sock.close()
            raise

    def _open_ring(self) -> None:
        """Asks for the ring (RING_OPEN); its reply carries the region's memfd. A refusal
        leaves the lane on the socket."""
        self._send(RING_OPEN, b"")
        try:
            data, fds, _, _ = socket.recv_fds(self._sock, 64, 1)
        except OSError as err:
            self.close()
            raise FastLaneError(f"weftd is not reachable: fast lane: {err}", "UNAVAILABLE") from None
        try:
            if len(data) < 8:
                self.close()
                raise FastLaneError("weftd closed the fast lane", "UNAVAILABLE")
            code, flags = struct.unpack_from("<II", data)
            if code != 0 or not fds or len(data) != 16:
                if flags & 2:
                    self.close()
                return                 # refused: the socket carries the frames
            self.ring = _Ring(fds[0], struct.unpack_from("<Q", data, 8)[0], self._sock)
        finally:
            for fd in fds:
                os.close(fd)

    def close(self) -> None:
        self.broken = True
        try:
            self._sock.close()
        except OSError:
            pass
        if self.ring is not None:
            self.ring.close()

    def fits(self, request) -> bool:
        return not self.broken and request.ByteSize() + 4 <= MAX_REQUEST_BYTES

    def fits_bytes(self, nbytes: int) -> bool:
        """fits() for a request already serialized into `nbytes` bytes."""
        return not self.broken and nbytes + 4 <= MAX_REQUEST_BYTES

    def call(self, method: int, request, response_type, spin_s: float | None = None):
        """Sends `request` (a message, or its serialized bytes) and returns the parsed
        response; a daemon error becomes WeftError with the same message and status name as
        through gRPC. A Submit or Synchronize polls for its reply for `spin_s` (default
        SPIN_S) before blocking."""
        self._send(method, request if type(request) is bytes else request.SerializeToString())
        if method not in (SUBMIT, SYNCHRONIZE):
            spin_s = 0.0
        return response_type.FromString(self._receive(SPIN_S if spin_s is None else spin_s))

    def call_many(self, method: int, requests) -> list:
        """Sends each request and collects the replies, PIPELINE_WINDOW frames at a time: one
        entry per request, None for OK or the WeftError the daemon answered. A broken lane
        raises FastLaneError (what was sent before it may or may not have been served)."""
        results = []
        for start in range(0, len(requests), PIPELINE_WINDOW):
            window = requests[start:start + PIPELINE_WINDOW]
            for request in window:
                self._send(method, request.SerializeToString())
            for _ in window:
                try:
                    self._receive()
                    results.append(None)
                except FastLaneError:
                    raise
                except WeftError as err:
                    results.append(err)
        return results

    def send_quiet(self, body: bytes) -> None:
        """Sends a serialized SubmitRequest (neither synchronize nor run) as SUBMIT_QUIET: no
        reply unless it fails; a failure is kept as `quiet_error` when the next reply is read
        (or by poll_quiet)."""
        self._send(SUBMIT_QUIET, body)

    def send_unanswered_free(self, body: bytes) -> None:
        """Sends a serialized FreeArrayRequest as ARRAY_FREE_UNANSWERED: never answered."""
        self._send(ARRAY_FREE_UNANSWERED, body)

    def poll_quiet(self) -> None:
        """Reads the failures of quiet Submits that are in, without blocking. Only while no
        other reply is outstanding on the lane (everything readable then answers a quiet
        Submit)."""
        while not self.broken:
            try:
                n = self._try_frame()
                if n < 0:
                    return
            except OSError as err:
                self.close()
                raise FastLaneError(f"weftd is not reachable: fast lane: {err}", "UNAVAILABLE") from None
            try:
                _, quiet = self._receive_one(0.0, n)
            except FastLaneError:
                raise
            except WeftError:
                quiet = False
            if not quiet:                 # a reply nothing waited for: the lane is confused
                self.close()
                raise FastLaneError("fast lane: a reply that answers no request", "UNAVAILABLE")

    def take_quiet_error(self):
        """The first failure of a quiet Submit read so far (None if none), forgotten."""
        err, self.quiet_error = self.quiet_error, None
        return err

    def send(self, method: int, request, response_type) -> "PendingReply":
        """Sends `request` (a message, or its serialized bytes) without waiting: the daemon
        works on it while this process goes on.
        The reply must be collected (PendingReply.result) before the next call on this lane."""
        self._send(method, request if type(request) is bytes else request.SerializeToString())
        return PendingReply(self, response_type)

    def _call(self, method: int, body: bytes) -> bytes:
        self._send(method, body)
        return self._receive()

    def _send(self, method: int, body: bytes) -> None:
        try:
            header = _METHOD_HEADERS.get(method)
            if self.ring is not None:
                self.ring.put(header if header is not None else struct.pack("<I", method), body)
                return
            frame = (header if header is not None else struct.pack("<I", method)) + body
            if self._sock.send(frame) != len(frame):
                raise FastLaneError("fast lane: short send", "UNAVAILABLE")
        except OSError as err:
            self.close()
            raise FastLaneError(f"weftd is not reachable: fast lane: {err}", "UNAVAILABLE") from None
        except FastLaneError:
            self.close()
            raise

    def _try_frame(self) -> int:
        """One reply frame into the buffer if one is in: its length, else -1 (no waiting)."""
        ring = self.ring
        if ring is not None:
            if ring._native_take is not None:
                return ring.take_into(self._buf_address, _RECV_BYTES)
            return ring.take(self._view)
        try:
            return self._sock.recv_into(self._buf, _RECV_BYTES, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return -1

    def _wait_frame(self) -> int:
        """The next reply frame into the buffer, waiting for it: its length (0 when weftd closed
        the lane)."""
        if self.ring is not None:
            return self.ring.wait(self._view)
        return self._sock.recv_into(self._buf, _RECV_BYTES)

    def _poll(self, seconds: float) -> int:
        """Polls for a reply frame for up to `seconds`: its length, or -1 when none came. On a
        ring read in C the polling is in C too (at most 200 us per call, then Python looks at
        the clock again)."""
        ring = self.ring
        if ring is not None and ring._native_take is not None:
            take, address = ring.take_into, self._buf_address
            perf = time.perf_counter
            deadline = perf() + seconds
            while True:
                n = take(address, _RECV_BYTES, seconds)
                if n >= 0:
                    return n
                seconds = deadline - perf()
                if seconds <= 0:
                    return -1
        try_frame = self._try_frame
        deadline = time.perf_counter() + seconds
        while True:
            n = try_frame()
            if n >= 0 or time.perf_counter() >= deadline:
                return n

    def _receive(self, spin_s: float = 0.0, first_frame: int = -1) -> bytes:
        """The next reply's payload (a daemon error raised as WeftError). `first_frame`: the
        length of its first frame when the caller already received that into the buffer. The
        failures of quiet Submits sent before the request, read on the way, are kept as
        `quiet_error` (the first one) and the reply asked for is read on."""
        while True:
            payload, quiet = self._receive_one(spin_s, first_frame)
            if not quiet:
                return payload
            first_frame = -1

    def _receive_one(self, spin_s: float, first_frame: int):
        """One reply: (payload, whether it is a quiet Submit's failure, kept as quiet_error);
        another daemon error is raised as WeftError."""
        try:
            parts = []
            size = 0
            closing = False
            while True:
                n = first_frame if not parts else -1
                if n < 0 and spin_s > 0 and not parts:
                    n = self._poll(spin_s)
                if n < 0:
                    n = self._wait_frame()
                if n < 8:
                    raise FastLaneError("weftd closed the fast lane", "UNAVAILABLE")
                code, flags = struct.unpack_from("<II", self._buf)
                quiet = bool(flags & QUIET_REPLY_FLAG)
                size += n - 8
                if size > MAX_REPLY_BYTES:
                    raise FastLaneError("fast lane: reply too large", "RESOURCE_EXHAUSTED")
                parts.append(bytes(self._view[8:n]))
                closing = closing or bool(flags & 2)
                if not flags & 1:
                    break
        except OSError as err:
            self.close()
            raise FastLaneError(f"weftd is not reachable: fast lane: {err}", "UNAVAILABLE") from None
        except FastLaneError:
            self.close()
            raise
        payload = b"".join(parts)
        if closing:
            self.close()
        if quiet:
            if self.quiet_error is None:
                self.quiet_error = WeftError(payload.decode("utf-8", "replace"), _CODE_NAMES.get(code))
            return b"", True
        if code != 0:
            raise WeftError(payload.decode("utf-8", "replace"), _CODE_NAMES.get(code))
        return payload, False


class PendingReply:
    """The reply of a request sent with FastLane.send, shaped like the grpc future the
    Runtime keeps for an asynchronous Submit: done() and result()."""

    def __init__(self, lane: FastLane, response_type):
        self._lane = lane
        self._type = response_type
        self._response = None
        self._payload = None        # the reply's bytes, once received
        self._error = None          # the daemon's error, once received
        self.ahead = None           # an array created ahead (weft._create_ahead) awaits it

    def done(self) -> bool:
        """Whether the reply is in: received now if it is (one non-blocking recv, no select),
        so that replies are collected in bulk with one system call each."""
        if self._payload is not None or self._error is not None or self._lane.broken:
            return True
        lane = self._lane
        try:
            n = lane._try_frame()
            if n < 0:
                return False
        except OSError:
            return True             # result() reports the broken connection
        try:
            self._payload = lane._receive(first_frame=n)
        except WeftError as err:
            self._error = err
        return True

    def check(self) -> None:
        """Waits for the reply and raises the daemon's error, if any, without parsing it."""
        if self._error is not None:
            raise self._error
        if self._payload is None:
            self._payload = self._lane._receive()

    def result(self):
        self.check()
        if self._response is None:
            self._response = self._type.FromString(self._payload)
        return self._response
