/* weft._stream_ops: what an ordered launch on framework GPU memory does per launch besides the
 * launch itself (weft/interop/cuda_order.py, stream memory operations), in C.
 *
 * Owns two things:
 * - op(function, get_current, context, stream, address, value, flags): one 64-bit stream memory
 *   operation (the driver's cuStreamWriteValue64_v2 or cuStreamWaitValue64_v2 at `function`,
 *   cuCtxGetCurrent at `get_current`: addresses weft/_cuda_ipc.py took from its ctypes handle
 *   of libcuda) on this process's `stream`; returns the driver's result code. On the legacy
 *   default stream (0), which names the current context's, it calls nothing and returns
 *   CUDA_ERROR_INVALID_CONTEXT (201) when `context` is not current: the caller pushes it and
 *   calls again (in Python). The addresses are trusted as ctypes trusts them; 0 is refused.
 * - value_command(inner, value): the framed SubmitRequest.commands element
 *   {cuda_value: inner + {value}, origin: {}} that _ValueOrder.command builds in Python (the
 *   same bytes: tests/interop/test_stream_ops.py). */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>

#include <stdint.h>
#include <string.h>

typedef int (*StreamValueFn)(void* stream, unsigned long long address, uint64_t value, unsigned int flags);
typedef int (*GetCurrentFn)(void** context);

enum { kInvalidContext = 201 };

static int Address(PyObject* o, uintptr_t* out, const char* what) {
  if (!PyLong_Check(o)) {
    PyErr_Format(PyExc_TypeError, "op: %s is an int", what);
    return -1;
  }
  *out = (uintptr_t)PyLong_AsUnsignedLongLong(o);
  return PyErr_Occurred() ? -1 : 0;
}

static PyObject* op(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  (void)self;
  if (argc != 7) {
    PyErr_SetString(PyExc_TypeError, "op(function, get_current, context, stream, address, value, flags)");
    return NULL;
  }
  static const char* const kNames[] = {"function", "get_current", "context", "stream", "address", "value", "flags"};
  uintptr_t v[7];
  for (int i = 0; i < 7; ++i)
    if (Address(argv[i], &v[i], kNames[i]) != 0) return NULL;
  if (v[0] == 0 || v[1] == 0) {
    PyErr_SetString(PyExc_ValueError, "op: the driver's function addresses are 0");
    return NULL;
  }
  if (v[6] > 0xFFFFFFFFu) {
    PyErr_SetString(PyExc_ValueError, "op: flags out of range");
    return NULL;
  }
  const StreamValueFn fn = (StreamValueFn)v[0];
  const GetCurrentFn get_current = (GetCurrentFn)v[1];
  void* const stream = (void*)v[3];
  int rc = 0;
  Py_BEGIN_ALLOW_THREADS
  if (stream == NULL) {
    void* current = NULL;
    rc = get_current(&current);
    if (rc == 0 && (uintptr_t)current != v[2]) rc = kInvalidContext;
  }
  if (rc == 0) rc = fn(stream, (unsigned long long)v[4], (uint64_t)v[5], (unsigned int)v[6]);
  Py_END_ALLOW_THREADS
  return PyLong_FromLong(rc);
}

static size_t Varint(uint64_t x, unsigned char* out) {
  size_t n = 0;
  while (x >= 0x80) {
    out[n++] = (unsigned char)(x | 0x80);
    x >>= 7;
  }
  out[n++] = (unsigned char)x;
  return n;
}

static PyObject* value_command(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  (void)self;
  if (argc != 2 || !PyBytes_Check(argv[0]) || !PyLong_Check(argv[1])) {
    PyErr_SetString(PyExc_TypeError, "value_command(inner: bytes, value: int)");
    return NULL;
  }
  const uint64_t value = PyLong_AsUnsignedLongLong(argv[1]);
  if (PyErr_Occurred()) return NULL;
  const Py_ssize_t inner_len = PyBytes_Size(argv[0]);
  if (inner_len < 0 || inner_len > 4096) {
    PyErr_SetString(PyExc_ValueError, "value_command: the template is larger than a CudaValueCommand");
    return NULL;
  }
  /* inner + 0x20 varint(value): CudaValueCommand (field 4, varint) */
  unsigned char tail[11];
  tail[0] = 0x20;
  const size_t tail_len = 1 + Varint(value, tail + 1);
  const uint64_t cuda_value_len = (uint64_t)inner_len + tail_len;
  /* Command: 0x3a varint(len) cuda_value, 0x7a 0x00 (origin, empty) */
  unsigned char cv_len[10];
  const size_t cv_len_n = Varint(cuda_value_len, cv_len);
  const uint64_t cmd_len = 1 + cv_len_n + cuda_value_len + 2;
  /* SubmitRequest.commands: 0x0a varint(len) Command */
  unsigned char cmd_len_v[10];
  const size_t cmd_len_n = Varint(cmd_len, cmd_len_v);
  const Py_ssize_t total = (Py_ssize_t)(1 + cmd_len_n + cmd_len);
  PyObject* out = PyBytes_FromStringAndSize(NULL, total);
  if (out == NULL) return NULL;
  unsigned char* p = (unsigned char*)PyBytes_AsString(out);
  *p++ = 0x0a;
  memcpy(p, cmd_len_v, cmd_len_n);
  p += cmd_len_n;
  *p++ = 0x3a;
  memcpy(p, cv_len, cv_len_n);
  p += cv_len_n;
  memcpy(p, PyBytes_AsString(argv[0]), (size_t)inner_len);
  p += inner_len;
  memcpy(p, tail, tail_len);
  p += tail_len;
  *p++ = 0x7a;
  *p++ = 0x00;
  return out;
}

static PyMethodDef kMethods[] = {
    {"op", (PyCFunction)(void (*)(void))op, METH_FASTCALL,
     "op(function, get_current, context, stream, address, value, flags) -> the driver's result "
     "code (201 without a call: `context` is not current for the default stream)."},
    {"value_command", (PyCFunction)(void (*)(void))value_command, METH_FASTCALL,
     "value_command(inner, value) -> the framed SubmitRequest.commands element of a "
     "CudaValueCommand."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kModule = {
    PyModuleDef_HEAD_INIT, "weft._stream_ops",
    "Stream memory operations and value commands of ordered launches, in C "
    "(clients/python/native/stream_ops.c).",
    -1, kMethods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__stream_ops(void) { return PyModule_Create(&kModule); }
