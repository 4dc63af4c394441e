/* weft._lane_ring: the client's write of one request record into a fast lane's shared-memory
 * ring (layout: server/lane_ring.h; the Python side: weft/_fast_lane.py _Ring.put).
 *
 * Owns one thing: put(address, size, capacity, base, head, tail, header, body) copies
 * header + body as one record at `head` of the request area (a wrap marker first when the
 * record does not fit before the area's end) and publishes it by storing the new head with
 * release order; it returns the new head, or -1 when the area lacks room by the cached `tail`
 * (the caller re-reads the daemon's tail and waits, in Python). Every offset is checked against
 * the mapping's `size` before a byte is written. The daemon validates every record it reads
 * (docs/protocol.md "Ring"). */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>

#include <stdint.h>
#include <string.h>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "weft._lane_ring writes the ring's little-endian words; build it only on little-endian hosts"
#endif

enum {
  kRequestHead = 64, /* _Ring.REQUEST_HEAD: the u64 the daemon reads records up to */
};
static const uint32_t kWrap = 0xFFFFFFFFu;

static PyObject* put(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  if (argc != 8) {
    PyErr_SetString(PyExc_TypeError, "put(address, size, capacity, base, head, tail, header, body)");
    return NULL;
  }
  for (int i = 0; i < 6; ++i)
    if (!PyLong_Check(argv[i])) {
      PyErr_SetString(PyExc_TypeError, "put: address, size, capacity, base, head and tail are ints");
      return NULL;
    }
  if (!PyBytes_Check(argv[6]) || !PyBytes_Check(argv[7])) {
    PyErr_SetString(PyExc_TypeError, "put: header and body are bytes");
    return NULL;
  }
  const uintptr_t address = (uintptr_t)PyLong_AsUnsignedLongLong(argv[0]);
  const uint64_t size = PyLong_AsUnsignedLongLong(argv[1]);
  const uint64_t cap = PyLong_AsUnsignedLongLong(argv[2]);
  const uint64_t base = PyLong_AsUnsignedLongLong(argv[3]);
  uint64_t head = PyLong_AsUnsignedLongLong(argv[4]);
  const uint64_t tail = PyLong_AsUnsignedLongLong(argv[5]);
  if (PyErr_Occurred()) return NULL;
  const Py_ssize_t header_len = PyBytes_Size(argv[6]);
  const Py_ssize_t body_len = PyBytes_Size(argv[7]);
  const uint64_t n = (uint64_t)header_len + (uint64_t)body_len;
  const uint64_t rec = (4 + n + 7) & ~(uint64_t)7;
  if (address == 0 || cap < 8 || cap % 8 != 0 || base % 8 != 0 || base > size || cap > size - base ||
      size < kRequestHead + 8 || n > 0xFFFFFFF0u || rec > cap || head < tail || head - tail > cap) {
    PyErr_SetString(PyExc_ValueError, "put: the ring's layout or this record is out of range");
    return NULL;
  }
  const uint64_t pos = head % cap;
  const uint64_t contiguous = cap - pos;
  const uint64_t need = rec <= contiguous ? rec : contiguous + rec;
  if (cap - (head - tail) < need) return PyLong_FromLong(-1);
  char* area = (char*)address + base;
  uint64_t at = pos;
  if (rec > contiguous) { /* a wrap marker, then the record at the area's start */
    uint32_t wrap = kWrap;
    memcpy(area + pos, &wrap, 4);
    head += contiguous;
    at = 0;
  }
  const uint32_t len32 = (uint32_t)n;
  memcpy(area + at, &len32, 4);
  memcpy(area + at + 4, PyBytes_AsString(argv[6]), (size_t)header_len);
  memcpy(area + at + 4 + header_len, PyBytes_AsString(argv[7]), (size_t)body_len);
  head += rec;
  __atomic_store_n((uint64_t*)((char*)address + kRequestHead), head, __ATOMIC_RELEASE);
  return PyLong_FromUnsignedLongLong(head);
}

static PyMethodDef kMethods[] = {
    {"put", (PyCFunction)(void (*)(void))put, METH_FASTCALL,
     "put(address, size, capacity, base, head, tail, header, body) -> the new head, or -1 when "
     "the request area lacks room by `tail`."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kModule = {
    PyModuleDef_HEAD_INIT, "weft._lane_ring",
    "A fast lane ring's request write, in C (clients/python/native/lane_ring.c).", -1, kMethods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__lane_ring(void) { return PyModule_Create(&kModule); }
