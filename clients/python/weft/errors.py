"""weft's client-side exception: WeftError, raised for every error the daemon reports (a failed
RPC, or an asynchronous command error surfacing at a sync point), with the daemon's message,
the gRPC status code name and, when known, the user's file:line that issued the command."""
from __future__ import annotations


class WeftError(RuntimeError):
    """An error reported by weftd. `.code` is the gRPC status name ("INVALID_ARGUMENT"),
    `.origin` the "file:line" of the user code that issued the failing command (or None)."""

    def __init__(self, message: str, code: str | None = None, origin: str | None = None):
        self.message = message
        self.code = code
        self.origin = origin
        text = message
        if origin:
            text = f"{origin}: {text}"
        if code and code not in ("OK", "UNKNOWN"):
            text = f"{text} [{code}]"
        super().__init__(text)


def error_from_rpc(err) -> WeftError:
    """A WeftError for a grpc.RpcError, carrying the daemon's message and status name, and
    `.diagnostics` when the daemon sent a failed compile's diagnostics in its trailer."""
    try:
        code = err.code()
        code_name = code.name if code is not None else None
        details = err.details() or str(code)
    except Exception:  # noqa: BLE001 - not a call error (e.g. a bare RpcError)
        return WeftError(str(err))
    if code_name == "UNAVAILABLE":
        details = f"weftd is not reachable: {details}"
    error = WeftError(details, code_name)
    error.diagnostics = _trailer_diagnostics(err)
    return error


def _trailer_diagnostics(err) -> list:
    """The Diagnostic messages of the `weft-compile-diagnostics-bin` trailer (a serialized
    CompileResponse), or [] when there is none or it does not parse."""
    trailing = getattr(err, "trailing_metadata", None)
    trailer = dict(trailing() or ()).get("weft-compile-diagnostics-bin") if trailing else None
    if not trailer:
        return []
    from google.protobuf.message import DecodeError  # noqa: PLC0415

    from .v1 import module_pb2  # noqa: PLC0415 - generated stubs load with the runtime
    response = module_pb2.CompileResponse()
    try:
        response.ParseFromString(trailer)
    except DecodeError:
        return []
    return list(response.diagnostics)
