"""Devices as Warp shows them: wp.init, wp.get_devices/get_device/set_device, ScopedDevice,
the CUDA queries and wp.synchronize*. A Device describes one device the daemon owns ("cpu",
"cuda:0", ...); the default device is cuda:0 when the daemon has a GPU, else cpu (Warp's rule).
"""
from __future__ import annotations

import threading

from . import _runtime

__all__ = [
    "Device", "ScopedDevice", "init", "get_devices", "get_device", "set_device",
    "get_preferred_device", "get_cuda_devices", "get_cuda_device", "get_cuda_device_count",
    "is_cuda_available", "is_cpu_available", "is_device_available", "synchronize",
    "synchronize_device", "get_cuda_driver_version", "get_cuda_toolkit_version",
    "get_cuda_supported_archs", "print_diagnostics",
]


class Device:
    """One device of the daemon (Warp's wp.context.Device, minus streams and contexts)."""

    def __init__(self, info):
        self._info = info
        self.alias = info.name
        self.is_cpu = info.kind == "cpu"
        self.is_cuda = info.kind == "cuda"
        # False while the daemon lists a device it cannot yet hold arrays on or launch on.
        self.is_compute_supported = bool(getattr(info, "compute_supported", self.is_cpu))
        self.ordinal = int(info.name.split(":")[1]) if self.is_cuda and ":" in info.name else -1
        self.name = info.description or info.name
        self.arch = (info.compute_capability_major * 10 + info.compute_capability_minor
                     if self.is_cuda else 0)
        self.sm_count = info.cores if self.is_cuda else 0
        # the opt-in maximum shared memory of a block, bytes (Warp's attribute; 0 on the CPU)
        self.max_shared_memory_per_block = (int(getattr(info, "max_shared_memory_per_block", 0))
                                            if self.is_cuda else 0)
        self.is_uva = self.is_cuda
        # its session memory in weftd acts as the pool (weft/mempool.py)
        self.is_mempool_supported = self.is_cuda and self.is_compute_supported
        # array.ipc_handle() / wp.from_ipc_handle() share this device's arrays between client
        # processes (daemon tokens, docs/cuda-client.md), and wp.Event(interprocess=True) orders
        # their work (an event weftd opens and shares with the sessions of the same principal).
        self.is_ipc_supported = True
        self.is_primary = self.is_cuda

    @property
    def total_memory(self) -> int:
        return int(self._info.total_memory)

    @property
    def free_memory(self) -> int:
        """Free memory now (asks the daemon)."""
        for info in _runtime.get_runtime().call(
                _runtime.get_runtime().device_stub.List,
                _runtime.device_pb2.ListDevicesRequest()).devices:
            if info.name == self.alias:
                return int(info.free_memory)
        return int(self._info.free_memory)

    @property
    def context(self):
        return None

    @property
    def has_stream(self) -> bool:
        """A CUDA device always has the session's stream (weft/streams.py); the CPU has none."""
        return self.is_cuda

    @property
    def null_stream(self):
        """Warp's legacy default stream of the device: for a weft client the session's stream
        too (every wp.Stream of a device names it, weft/streams.py)."""
        from .streams import Stream  # noqa: PLC0415
        if getattr(self, "_null_stream", None) is None:
            self._null_stream = Stream(self)
        return self._null_stream

    @property
    def is_capturing(self) -> bool:
        """Whether this thread is capturing a graph on this device (weft/graph.py)."""
        from .graph import is_capturing  # noqa: PLC0415
        return is_capturing(self)

    @property
    def stream(self):
        """The current stream of this CUDA device (wp.get_stream)."""
        if not self.is_cuda:
            raise RuntimeError(f"Device {self.alias} is not a CUDA device: it has no streams")
        from .streams import get_stream  # noqa: PLC0415
        return get_stream(self)

    def __str__(self):
        return self.alias

    def __repr__(self):
        return f"'{self.alias}'"

    def __eq__(self, other):
        if isinstance(other, Device):
            return self.alias == other.alias
        if isinstance(other, str):
            if other == "cuda":
                return self.is_cuda and self == _current_cuda_device()
            return other == self.alias
        return NotImplemented

    def __hash__(self):
        return hash(self.alias)

    def __enter__(self):
        # Warp lets a device be used as `with device:`.
        self._scope = ScopedDevice(self)
        return self._scope.__enter__()

    def __exit__(self, *exc):
        self._scope.__exit__(*exc)


_devices_by_alias: dict = {}
_devices: list = []
_state = threading.local()
_default_device: Device | None = None


def _load_devices() -> None:
    rt = _runtime.get_runtime()
    if _devices and _devices_by_alias.get("_session") == rt.session_id:
        return
    _devices.clear()
    _devices_by_alias.clear()
    for info in rt.devices():
        device = Device(info)
        _devices.append(device)
        _devices_by_alias[device.alias] = device
    _devices_by_alias["_session"] = rt.session_id


def init() -> None:
    """Connects to weftd (starting a local one if needed) and loads its devices."""
    _load_devices()


def get_devices() -> list:
    """Every device of the daemon, CPU first."""
    _load_devices()
    return [d for d in _devices if d.is_cpu] + [d for d in _devices if not d.is_cpu]


def get_cuda_devices() -> list:
    _load_devices()
    return [d for d in _devices if d.is_cuda]


def get_cuda_device(ordinal=None) -> Device:
    """The CUDA device `ordinal` (None: the current CUDA device)."""
    if ordinal is None:
        device = _current_cuda_device()
        if device is None:
            raise RuntimeError("CUDA is not available in weftd")
        return device
    return get_device(f"cuda:{int(ordinal)}")


def get_cuda_device_count() -> int:
    return len(get_cuda_devices())


def is_cuda_available() -> bool:
    return get_cuda_device_count() > 0


def is_cpu_available() -> bool:
    _load_devices()
    return "cpu" in _devices_by_alias


def is_device_available(device) -> bool:
    _load_devices()
    return getattr(device, "alias", device) in _devices_by_alias


def get_cuda_driver_version() -> tuple | None:
    """(major, minor) of the CUDA driver weftd runs with (e.g. (13, 0)); None without one."""
    version = int(_runtime.get_runtime().device_listing().cuda_driver_version)
    return (version // 1000, (version % 1000) // 10) if version > 0 else None


def get_cuda_toolkit_version() -> tuple | None:
    """(major, minor) of the CUDA toolkit weftd compiles kernels with (its NVRTC: weft builds
    CUDA code in the daemon, not in this process); None without one."""
    text = _runtime.get_runtime().device_listing().nvrtc_version
    try:
        major, minor = (int(x) for x in text.split(".")[:2])
    except ValueError:
        return None
    return (major, minor)


def get_cuda_supported_archs() -> list:
    """The architectures weftd's NVRTC compiles for (75 for sm_75, ...), sorted; [] without it."""
    return sorted(int(a) for a in _runtime.get_runtime().device_listing().cuda_archs)


def print_diagnostics() -> dict:
    """Prints the client's and weftd's versions, the CUDA toolchain weftd runs with and the
    devices it owns; returns the same as a dict (Warp's wp.print_diagnostics; keys that describe
    Warp's native library are weftd's here)."""
    import importlib.metadata  # noqa: PLC0415
    import platform  # noqa: PLC0415
    import sys  # noqa: PLC0415

    import numpy as np  # noqa: PLC0415

    from . import __version__, config  # noqa: PLC0415

    rt = _runtime.get_runtime()
    listing = rt.device_listing()
    toolkit, driver = get_cuda_toolkit_version(), get_cuda_driver_version()
    info = {"warp_python": config.version, "weft": __version__, "numpy": np.__version__}
    for package in ("torch", "jax", "jaxlib", "cupy"):
        try:
            info[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            pass
    info.update({"python": sys.version, "platform": platform.platform(), "daemon": rt.address,
                 "session_host": bool(rt.hosted), "device_host": rt.host_device or None,
                 "cuda_enabled": any(d.is_cuda and d.is_compute_supported for d in get_devices()),
                 "cuda_toolkit": f"{toolkit[0]}.{toolkit[1]}" if toolkit else None,
                 "cuda_driver": f"{driver[0]}.{driver[1]}" if driver else None,
                 "nvrtc": listing.nvrtc_version or None,
                 "cuda_archs": get_cuda_supported_archs()})
    devices = []
    for d in get_devices():
        entry = {"alias": d.alias, "name": d.name, "memory_gb": round(d.total_memory / (1 << 30), 1)}
        if d.is_cuda:
            entry.update({"arch": f"sm_{d.arch}", "sm_count": d.sm_count,
                          "compute_supported": d.is_compute_supported})
        devices.append(entry)
    info["devices"] = devices
    lines = ["Software"]
    for label, key in (("Warp API:", "warp_python"), ("weft client:", "weft"), ("NumPy:", "numpy"),
                       ("PyTorch:", "torch"), ("JAX:", "jax"), ("CuPy:", "cupy"),
                       ("Python:", "python"), ("Platform:", "platform")):
        if key in info:
            lines.append(f"  {label:<18}{str(info[key]).splitlines()[0]}")
    lines += ["", "weftd", f"  {'Address:':<18}{info['daemon']}",
              f"  {'Session host:':<18}"
              + (f"the process of {info['device_host']}'s sessions" if info["device_host"]
                 else "yes" if info["session_host"] else "no"),
              f"  {'CUDA driver:':<18}{info['cuda_driver'] or 'none'}",
              f"  {'NVRTC:':<18}{info['nvrtc'] or 'none'}",
              f"  {'CUDA archs:':<18}{', '.join(f'sm_{a}' for a in info['cuda_archs']) or 'none'}",
              "", "Devices"]
    for entry in devices:
        extra = f"  {entry['arch']}, {entry['sm_count']} SMs" if "arch" in entry else ""
        lines.append(f"  {entry['alias']:<10}{entry['name']}  {entry['memory_gb']} GiB{extra}")
    print("\n".join(lines))
    return info


def _current_cuda_device() -> Device | None:
    current = get_device()
    if current.is_cuda:
        return current
    cuda = get_cuda_devices()
    return cuda[0] if cuda else None


def get_preferred_device() -> Device:
    _load_devices()
    cuda = [d for d in _devices if d.is_cuda and d.is_compute_supported]
    return cuda[0] if cuda else _devices_by_alias["cpu"]


def get_device(ident=None) -> Device:
    """The Device for `ident` ("cpu", "cuda", "cuda:N", a Device); None: the current one."""
    if isinstance(ident, Device):
        return ident
    _load_devices()
    if ident is None:
        stack = getattr(_state, "stack", None)
        if stack:
            return stack[-1]
        return _default_device if _default_device is not None else get_preferred_device()
    if not isinstance(ident, str):
        # torch.device and similar expose .type / .index
        kind = getattr(ident, "type", None)
        if kind is not None:
            index = getattr(ident, "index", None)
            ident = kind if index is None else f"{kind}:{index}"
        else:
            raise ValueError(f"Invalid device identifier: {ident}")
    if ident == "cuda":
        device = _current_cuda_device()
        if device is None:
            raise ValueError("Invalid device identifier: cuda (the daemon has no CUDA device)")
        return device
    device = _devices_by_alias.get(ident)
    if device is None or ident == "_session":
        raise ValueError(f"Invalid device identifier: {ident}")
    return device


def set_device(ident) -> None:
    """Sets the default device of this process."""
    global _default_device
    _default_device = get_device(ident)


class ScopedDevice:
    """`with wp.ScopedDevice("cpu"):` makes the device the default inside the block."""

    def __init__(self, device):
        self.device = get_device(device)

    def __enter__(self):
        stack = getattr(_state, "stack", None)
        if stack is None:
            stack = _state.stack = []
        stack.append(self.device)
        return self.device

    def __exit__(self, exc_type, exc_value, traceback):
        _state.stack.pop()


def synchronize() -> None:
    """Waits for every command this process issued; raises the first asynchronous error."""
    rt = _runtime.get_runtime()
    if rt.captures:          # a graph being captured: no host wait in its thread (Warp's error)
        from .graph import refuse_host_wait  # noqa: PLC0415
        refuse_host_wait("device")
    rt.synchronize()


def synchronize_device(device=None) -> None:
    """Waits for the commands issued on `device` (weft: every device of this session)."""
    device = get_device(device)
    from .graph import refuse_host_wait  # noqa: PLC0415
    refuse_host_wait("device", device)
    _runtime.get_runtime().synchronize()
