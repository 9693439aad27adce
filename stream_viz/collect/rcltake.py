"""Take serialized messages with the publisher's gid, through rcl itself (ctypes).

rclpy's ``take_message`` gives the source and receive stamps and the sequence number but not
the publisher gid that rcl's ``rmw_message_info_t`` carries. The gid tells which publisher of a
multi-publisher topic sent a message (its ``endpoint_gid`` in the graph). `RclTake` calls
``rcl_take_serialized_message`` on the subscription handle rclpy holds, into one reusable
buffer: no Python message object, no copy of the payload unless asked for.

The structure layouts are rmw's (Jazzy, ``RMW_GID_STORAGE_SIZE`` 16). They are checked on the
first message taken: its gid must name the running rmw implementation and its receive stamp must
be the present; otherwise `RclTake` switches itself off and the caller takes through rclpy
(`available` is False and stays so).
"""

from __future__ import annotations

import ctypes
import struct
import time
from collections.abc import Callable
from typing import Any

from stream_viz.collect.cdr import header_stamp_ns

GID_SIZE = 16
RET_OK = 0
RET_TAKE_FAILED = 401  # RCL_RET_SUBSCRIPTION_TAKE_FAILED: nothing waiting
HEAD = 48  # bytes of a message copied for the readers of fixed fields (header stamp, service event)


class Allocator(ctypes.Structure):
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p),
                ("reallocate", ctypes.c_void_p), ("zero_allocate", ctypes.c_void_p),
                ("state", ctypes.c_void_p)]


class _Uint8Array(ctypes.Structure):  # rcutils_uint8_array_t = rmw_serialized_message_t
    _fields_ = [("buffer", ctypes.POINTER(ctypes.c_uint8)), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", Allocator)]


class _Gid(ctypes.Structure):
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_uint8 * GID_SIZE)]


class _MessageInfo(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64),
                ("reception_sequence_number", ctypes.c_uint64),
                ("publisher_gid", _Gid), ("from_intra_process", ctypes.c_bool)]


# One C call per message reads what we need of the two structures (attribute access through
# ctypes costs more than the take): source, received, sequence number, (reception number and
# the gid's implementation pointer skipped) gid bytes; the buffer's address and length.
_INFO = struct.Struct("=qqQ16x16s").unpack_from
_BUFFER = struct.Struct("@PNN").unpack_from
_STAMP_LE = struct.Struct("<BBxxiI").unpack_from  # encapsulation 00 01 (CDR, little endian), stamp


def _loaded(name: str) -> str | None:
    """Path of the shared library ``name`` this process has loaded (rclpy loads rcl), or None."""
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                path = line.rsplit(None, 1)[-1]
                if path.endswith("/" + name):
                    return path
    except OSError:
        pass
    return None


def rcl_libraries() -> tuple[ctypes.CDLL, ctypes.CDLL]:
    """The rcl and rcutils libraries rclpy has loaded, with the default allocator's return type set."""
    path_rcl, path_utils = _loaded("librcl.so"), _loaded("librcutils.so")
    if path_rcl is None or path_utils is None:
        raise OSError("librcl.so / librcutils.so not loaded (import rclpy first)")
    rcl, rcutils = ctypes.CDLL(path_rcl), ctypes.CDLL(path_utils)
    rcutils.rcutils_get_default_allocator.restype = Allocator
    return rcl, rcutils


# A record sink: (received ns, source ns, size, sequence number, gid, head bytes or the payload).
Sink = Callable[[int, int, int, int, bytes, bytes], None]
# A window's add: (received ns, source ns, size, sequence number, gid[, message age ns]).
Add = Callable[..., None]
Age = Callable[[int, int], int]  # (received ns, header stamp ns) -> message age ns


class RclTake:
    """Takes serialized messages with their publisher gid from rclpy subscriptions.

    Parameters
    ----------
    rmw : str
        The rmw implementation rclpy runs (``rclpy.get_rmw_implementation_identifier()``); the
        first gid taken must name it.
    """

    def __init__(self, rmw: str) -> None:
        self.rmw = rmw.encode()
        self.available = False
        self.why = ""
        self._checked = self._allocated = False
        self._view: memoryview | None = None  # of the serialized buffer, while rmw keeps it
        self._view_of: tuple[int, int] | None = None
        try:
            self._setup()
            self.available = True
        except (OSError, AttributeError, ValueError) as e:
            self.why = f"rcl take with publisher gids unavailable: {e}"

    def _setup(self) -> None:
        rcl, rcutils = rcl_libraries()
        self._alloc = rcutils.rcutils_get_default_allocator()
        self._buf = _Uint8Array()
        init = rcutils.rcutils_uint8_array_init
        init.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        if init(ctypes.byref(self._buf), 4096, ctypes.byref(self._alloc)) != RET_OK:
            raise OSError("rcutils_uint8_array_init failed")
        self._allocated = True
        self._fini = rcutils.rcutils_uint8_array_fini
        self._fini.argtypes = [ctypes.c_void_p]
        take = rcl.rcl_take_serialized_message
        # no argtypes: the arguments are built as ctypes objects once per drain, not converted
        # on every call
        take.restype = ctypes.c_int
        self._take = take
        self._info = _MessageInfo()

    def drain(self, handle: Any, add: Add | None = None, age: Age | None = None,
              sink: Sink | None = None, payload: bool = False) -> int:
        """Take every waiting message of an rclpy subscription ``handle``; return how many.

        The caller holds the handle (``with handle:``). Each message's record goes to ``add``
        (a `TopicWindow.add`; given ``age``, a type with a header, the message age too: ``age(received,
        header stamp)``), or,
        given a ``sink``, there with the first `HEAD` bytes (the whole payload with ``payload``).
        """
        take, string_at, unpack_info, unpack_buffer = self._take, ctypes.string_at, _INFO, _BUFFER
        args = (ctypes.c_void_p(handle.pointer), ctypes.byref(self._buf), ctypes.byref(self._info), None)
        info, buf = memoryview(self._info).cast("B"), memoryview(self._buf).cast("B")
        n = 0
        while take(*args) == RET_OK:
            if not self._checked and not self._check():
                return n
            src, recv, seq, gid = unpack_info(info)
            addr, size, capacity = unpack_buffer(buf)
            n += 1
            if sink is not None:
                sink(recv, src, size, seq, gid, string_at(addr, size if payload else min(size, HEAD)))
            elif age is not None:
                stamp = self._stamp(addr, size, capacity)
                add(recv, src, size, seq, gid, None if stamp is None else age(recv, stamp))
            else:
                add(recv, src, size, seq, gid)
        return n

    def _stamp(self, addr: int, size: int, capacity: int) -> int | None:
        """The header stamp of the message in the buffer, read in place (a view of the buffer is
        kept until rmw reallocates it: copying 12 bytes out costs more than reading them)."""
        if size < 12:
            return None
        if self._view_of != (addr, capacity):
            self._view = memoryview((ctypes.c_char * capacity).from_address(addr)).cast("B")
            self._view_of = (addr, capacity)
        e0, kind, sec, nanosec = _STAMP_LE(self._view)
        if e0 != 0 or kind != 1:  # not little-endian CDR: the general reader
            return header_stamp_ns(bytes(self._view[:12]))
        return None if sec == 0 and nanosec == 0 else sec * 1_000_000_000 + nanosec

    def _check(self) -> bool:
        """Check the first message's info against what it must be; switch off when it is not."""
        info = self._info
        ident = info.publisher_gid.implementation_identifier
        recv_s = info.received_timestamp / 1e9
        if ident != self.rmw or abs(recv_s - time.time()) > 3600:
            self.available = False
            self.why = (f"rmw_message_info_t layout not as expected (gid names {ident!r}, not "
                        f"{self.rmw.decode()!r}); taking through rclpy without publisher gids")
            return False
        self._checked = True
        return True

    def close(self) -> None:
        """Free the buffer."""
        if self._view is not None:
            self._view.release()
            self._view = self._view_of = None
        if self._allocated:
            self._fini(ctypes.byref(self._buf))
        self.available = self._checked = self._allocated = False
