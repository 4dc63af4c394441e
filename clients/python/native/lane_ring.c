/* weft._lane_ring: the client's side of a fast lane's shared-memory ring in C (layout:
 * server/lane_ring.h; the Python side: weft/_fast_lane.py _Ring.put and _Ring.take).
 *
 * put(address, size, capacity, base, head, tail, header, body) copies
 * header + body as one record at `head` of the request area (a wrap marker first when the
 * record does not fit before the area's end) and publishes it by storing the new head with
 * release order; it returns the new head, or -1 when the area lacks room by the cached `tail`
 * (the caller re-reads the daemon's tail and waits, in Python).
 *
 * take(address, size, capacity, base, tail, out, out_len, spin_ns) looks for the next reply
 * record at `tail` of the reply area, polling the daemon's reply head for up to `spin_ns`
 * nanoseconds (at most kMaxSpinNs per call: the caller loops for longer waits, so that the GIL is
 * held no longer than a short C call holds it); -1 when none came, else it copies the record's
 * frame to `out` (a buffer of `out_len` bytes the caller keeps alive), releases the record (the
 * new tail stored with release order) and returns (the frame's length, the new tail). A record
 * longer than `out_len` or reaching past the area, or a head behind the tail or more than the
 * area ahead, raises ValueError and leaves the tail where it was.
 *
 * Every offset is checked against the mapping's `size` before a byte is read or written. The
 * daemon validates every record it reads (docs/protocol.md "Ring"). */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>

#include <stdint.h>
#include <string.h>
#include <time.h>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "weft._lane_ring writes the ring's little-endian words; build it only on little-endian hosts"
#endif

enum {
  kRequestHead = 64, /* _Ring.REQUEST_HEAD: the u64 the daemon reads records up to */
  kReplyHead = 256,  /* _Ring.REPLY_HEAD: the u64 the daemon publishes reply records up to */
  kReplyTail = 320,  /* _Ring.REPLY_TAIL: the u64 this process releases reply records up to */
};
static const uint64_t kMaxSpinNs = 200000; /* one take() call polls at most this long */
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

static uint64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static inline void cpu_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#elif defined(__aarch64__)
  __asm__ __volatile__("yield");
#endif
}

static PyObject* take(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  if (argc != 8) {
    PyErr_SetString(PyExc_TypeError, "take(address, size, capacity, base, tail, out, out_len, spin_ns)");
    return NULL;
  }
  for (int i = 0; i < 8; ++i)
    if (!PyLong_Check(argv[i])) {
      PyErr_SetString(PyExc_TypeError, "take: every argument is an int");
      return NULL;
    }
  const uintptr_t address = (uintptr_t)PyLong_AsUnsignedLongLong(argv[0]);
  const uint64_t size = PyLong_AsUnsignedLongLong(argv[1]);
  const uint64_t cap = PyLong_AsUnsignedLongLong(argv[2]);
  const uint64_t base = PyLong_AsUnsignedLongLong(argv[3]);
  uint64_t tail = PyLong_AsUnsignedLongLong(argv[4]);
  const uintptr_t out = (uintptr_t)PyLong_AsUnsignedLongLong(argv[5]);
  const uint64_t out_len = PyLong_AsUnsignedLongLong(argv[6]);
  uint64_t spin_ns = PyLong_AsUnsignedLongLong(argv[7]);
  if (PyErr_Occurred()) return NULL;
  if (address == 0 || out == 0 || cap < 16 || cap % 8 != 0 || base % 8 != 0 || base > size ||
      cap > size - base || size < kReplyTail + 8 || tail % 8 != 0) {
    PyErr_SetString(PyExc_ValueError, "take: the ring's layout is out of range");
    return NULL;
  }
  if (spin_ns > kMaxSpinNs) spin_ns = kMaxSpinNs;
  const uint64_t* head_word = (const uint64_t*)((const char*)address + kReplyHead);
  uint64_t head = __atomic_load_n(head_word, __ATOMIC_ACQUIRE);
  if (head == tail && spin_ns > 0) {
    const uint64_t until = now_ns() + spin_ns;
    unsigned polls = 0;
    while ((head = __atomic_load_n(head_word, __ATOMIC_ACQUIRE)) == tail) {
      cpu_relax();
      if ((++polls & 31) == 0 && now_ns() >= until) break;
    }
  }
  if (head == tail) return PyLong_FromLong(-1);
  if (head < tail || head - tail > cap) {
    PyErr_SetString(PyExc_ValueError, "take: the ring's reply head is out of range");
    return NULL;
  }
  const char* area = (const char*)address + base;
  uint64_t pos = tail % cap;
  uint32_t n = 0;
  memcpy(&n, area + pos, 4);
  if (n == kWrap) {
    tail += cap - pos;
    pos = 0;
    memcpy(&n, area, 4);
  }
  if (n > out_len || (uint64_t)n + 4 > cap - pos) {
    PyErr_SetString(PyExc_ValueError, "take: a ring record larger than a reply frame");
    return NULL;
  }
  memcpy((void*)out, area + pos + 4, n);
  tail += (4 + (uint64_t)n + 7) & ~(uint64_t)7;
  PyObject* result = Py_BuildValue("(IK)", n, (unsigned long long)tail);
  if (result == NULL) return NULL; /* the record stays unreleased */
  __atomic_store_n((uint64_t*)((char*)address + kReplyTail), tail, __ATOMIC_RELEASE);
  return result;
}

static PyMethodDef kMethods[] = {
    {"put", (PyCFunction)(void (*)(void))put, METH_FASTCALL,
     "put(address, size, capacity, base, head, tail, header, body) -> the new head, or -1 when "
     "the request area lacks room by `tail`."},
    {"take", (PyCFunction)(void (*)(void))take, METH_FASTCALL,
     "take(address, size, capacity, base, tail, out, out_len, spin_ns) -> -1, or (length, new "
     "tail) of the next reply record (its frame copied to `out`, the record released)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kModule = {
    PyModuleDef_HEAD_INIT, "weft._lane_ring",
    "A fast lane ring's request write and reply read, in C (clients/python/native/lane_ring.c).",
    -1, kMethods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__lane_ring(void) { return PyModule_Create(&kModule); }
