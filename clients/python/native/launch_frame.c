/* weft._launch_frame: the launch command of wp.launch's common case, built in C.
 *
 * Owns one thing: turning (a kernel's launch plan, the launch dimensions, the arguments, the
 * device, the caller's origin field) into the framed SubmitRequest.commands element that
 * weft/_kernel/launch.py would build in Python for the same launch, byte for byte. It takes
 * only the arguments the Python fast path (_pack_fast) takes without conversion: weft arrays
 * whose cached ArgValue field is still valid (the identity checks of _array_arg) and whose
 * dtype, ndim and device match the parameter (an array's ctypes descriptor stands for its
 * array, which replaces it in the argument list as _pack_fast's resolution does), Python floats
 * and ints for float32/float64 parameters, Python ints in range for integer parameters.
 * Anything else (a NumPy array, a struct, a vector, a Torch tensor, a bool, a NaN float32, an
 * out-of-range int, a stale cache) returns None, and the caller goes the Python way, which
 * converts it or raises the error. Nothing here decides what is valid beyond what the Python path already decided: the
 * daemon validates every argument again (docs/security.md).
 *
 * Built against the stable ABI (Py_LIMITED_API, Python 3.10+) so one .abi3.so serves every
 * later CPython; little-endian hosts only (the Python path packs '<' formats). */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <string.h>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "weft._launch_frame packs little-endian values; build it only on little-endian hosts"
#endif

/* Tags of the messages the frame nests (proto/weft/v1/exec.proto; all field numbers < 16). */
enum {
  kSubmitCommands = 0x0A, /* SubmitRequest.commands (1) */
  kCommandLaunch = 0x1A,  /* Command.launch (3) */
  kLaunchDim = 0x1A,      /* LaunchCommand.dim (3), packed */
  kLaunchArgs = 0x22,     /* LaunchCommand.args (4) */
  kArgRaw = 0x0A,         /* ArgValue.raw (1) */
};

enum ParamKind { kArray = 1, kFloat32 = 2, kFloat64 = 3, kInt = 4 };

typedef struct {
  int kind;
  PyObject* elem_text; /* arrays: the dtype text the parameter asks for; NULL = any */
  long ndim;           /* arrays */
  int size;            /* ints: bytes */
  int is_unsigned64;   /* ints: uint64 (range checked as unsigned) */
  long long lo, hi;    /* ints other than uint64: the range */
} ParamSpec;

typedef struct {
  PyObject* template_bytes; /* the LaunchCommand's fields before dim (module, kernel, device) */
  Py_ssize_t n;
  ParamSpec params[];
} LaunchSpec;

static const char* kCapsuleName = "weft._launch_frame.spec";

/* Set once by configure(): weft.array.array, weft.array.array_t, and interned names. */
static PyObject* g_array_type;
static PyObject* g_ctype_type;
static PyObject *s_dict, *s_mirror, *s_handle, *s_byte_offset, *s_shape, *s_strides, *s_dtype, *s_device,
    *s_weft_value, *s_ref_attr;

static void free_spec(LaunchSpec* spec) {
  Py_XDECREF(spec->template_bytes);
  for (Py_ssize_t i = 0; i < spec->n; ++i) Py_XDECREF(spec->params[i].elem_text);
  PyMem_Free(spec);
}

static void spec_capsule_free(PyObject* capsule) {
  LaunchSpec* spec = (LaunchSpec*)PyCapsule_GetPointer(capsule, kCapsuleName);
  if (!spec) {
    PyErr_Clear();
    return;
  }
  free_spec(spec);
}

/* spec(template_bytes, params) -> capsule. params: a sequence of tuples, one per kernel
 * parameter: (1, elem_text or None, ndim) an array, (2,) float32, (3,) float64,
 * (4, size, lo, hi) an integer of `size` bytes in [lo, hi]. */
static PyObject* make_spec(PyObject* self, PyObject* args) {
  PyObject *template_bytes, *params;
  if (!PyArg_ParseTuple(args, "SO:spec", &template_bytes, &params)) return NULL;
  Py_ssize_t n = PySequence_Size(params);
  if (n < 0) return NULL;
  LaunchSpec* spec = (LaunchSpec*)PyMem_Calloc(1, sizeof(LaunchSpec) + (size_t)n * sizeof(ParamSpec));
  if (!spec) return PyErr_NoMemory();
  Py_INCREF(template_bytes);
  spec->template_bytes = template_bytes;
  spec->n = 0;
  for (Py_ssize_t i = 0; i < n; ++i) {
    PyObject* item = PySequence_GetItem(params, i);
    if (!item) goto fail;
    ParamSpec* p = &spec->params[i];
    spec->n = i + 1; /* freed on failure from here on */
    int kind = 0;
    PyObject* elem = Py_None;
    long ndim = 0;
    int size = 0;
    PyObject *lo = NULL, *hi = NULL;
    int ok = PyTuple_Check(item) && PyTuple_Size(item) >= 1;
    if (ok) {
      kind = (int)PyLong_AsLong(PyTuple_GetItem(item, 0));
      ok = !PyErr_Occurred();
    }
    if (ok && kind == kArray) ok = PyArg_ParseTuple(item, "iOl", &kind, &elem, &ndim);
    if (ok && kind == kInt) ok = PyArg_ParseTuple(item, "iiO!O!", &kind, &size, &PyLong_Type, &lo, &PyLong_Type, &hi);
    Py_DECREF(item);
    if (!ok) {
      if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "spec: each parameter is a tuple (kind, ...)");
      goto fail;
    }
    p->kind = kind;
    if (kind == kArray) {
      if (elem != Py_None) {
        if (!PyUnicode_Check(elem)) {
          PyErr_SetString(PyExc_TypeError, "spec: an array's element type is a str or None");
          goto fail;
        }
        Py_INCREF(elem);
        p->elem_text = elem;
      }
      p->ndim = ndim;
    } else if (kind == kInt) {
      if (size != 1 && size != 2 && size != 4 && size != 8) {
        PyErr_SetString(PyExc_ValueError, "spec: an integer has 1, 2, 4 or 8 bytes");
        goto fail;
      }
      p->size = size;
      int overflow = 0;
      long long l = PyLong_AsLongLongAndOverflow(lo, &overflow);
      if (overflow || (l == -1 && PyErr_Occurred())) goto fail_range;
      long long h = PyLong_AsLongLongAndOverflow(hi, &overflow);
      if (overflow > 0 && size == 8 && l == 0) {
        p->is_unsigned64 = 1; /* [0, 2**64 - 1] */
      } else if (overflow || (h == -1 && PyErr_Occurred())) {
        goto fail_range;
      }
      p->lo = l;
      p->hi = h;
    } else if (kind != kFloat32 && kind != kFloat64) {
      PyErr_Format(PyExc_ValueError, "spec: unknown parameter kind %d", kind);
      goto fail;
    }
  }
  PyObject* capsule = PyCapsule_New(spec, kCapsuleName, spec_capsule_free);
  if (!capsule) goto fail;
  return capsule;
fail_range:
  if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "spec: integer range out of 64 bits");
fail:
  free_spec(spec);
  return NULL;
}

static PyObject* configure(PyObject* self, PyObject* args) {
  PyObject *array_type, *ctype_type, *ref_attr;
  if (!PyArg_ParseTuple(args, "OOU:configure", &array_type, &ctype_type, &ref_attr)) return NULL;
  Py_INCREF(array_type);
  Py_INCREF(ctype_type);
  Py_INCREF(ref_attr);
  Py_XDECREF(g_array_type);
  Py_XDECREF(g_ctype_type);
  Py_XDECREF(s_ref_attr);
  g_array_type = array_type;
  g_ctype_type = ctype_type;
  s_ref_attr = ref_attr;
  Py_RETURN_NONE;
}

static size_t varint_len(uint64_t v) {
  size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}

static char* put_varint(char* out, uint64_t v) {
  while (v >= 0x80) {
    *out++ = (char)((v & 0x7F) | 0x80);
    v >>= 7;
  }
  *out++ = (char)v;
  return out;
}

/* 1: `a` equals `b` (==); 0: not, or an error (cleared: the Python path will see it). */
static int equal(PyObject* a, PyObject* b) {
  if (a == b) return 1;
  int r = PyObject_RichCompareBool(a, b, Py_EQ);
  if (r < 0) {
    PyErr_Clear();
    return 0;
  }
  return r;
}

/* 1: `value.<name>` is `expected` (identity) or, unless `identity`, equals it (==); 0
 * otherwise (errors cleared: the Python path will see them). */
static int attr_matches(PyObject* value, PyObject* name, PyObject* expected, int identity) {
  PyObject* got = PyObject_GetAttr(value, name);
  if (!got) {
    PyErr_Clear();
    return 0;
  }
  int same = identity ? got == expected : equal(got, expected);
  Py_DECREF(got);
  return same;
}

/* The cached LaunchCommand.args field of weft array `value` for parameter `p` on `device`
 * (a new reference), or NULL when the Python path must decide (no error set). Mirrors
 * _pack_fast's array branch with _array_arg's cache hit. */
static PyObject* array_field(PyObject* value, const ParamSpec* p, PyObject* device) {
  int is_array = PyObject_IsInstance(value, g_array_type);
  if (is_array <= 0) {
    if (is_array < 0) PyErr_Clear();
    return NULL; /* a framework tensor, a NumPy array, None: the Python path */
  }
  PyObject* mirror = PyObject_GetAttr(value, s_mirror);
  if (!mirror) {
    PyErr_Clear();
    return NULL;
  }
  int mirrored = mirror != Py_None;
  Py_DECREF(mirror);
  if (mirrored) return NULL;
  PyObject* dict = PyObject_GetAttr(value, s_dict);
  if (!dict) {
    PyErr_Clear();
    return NULL;
  }
  PyObject* cached = PyDict_Check(dict) ? PyDict_GetItemWithError(dict, s_ref_attr) : NULL;
  Py_XINCREF(cached);
  Py_DECREF(dict);
  if (!cached) {
    PyErr_Clear();
    return NULL;
  }
  PyObject* field = NULL;
  if (PyTuple_Check(cached) && PyTuple_Size(cached) >= 11 &&
      attr_matches(value, s_handle, PyTuple_GetItem(cached, 0), 0) &&
      attr_matches(value, s_byte_offset, PyTuple_GetItem(cached, 1), 0) &&
      attr_matches(value, s_shape, PyTuple_GetItem(cached, 2), 1) &&
      attr_matches(value, s_strides, PyTuple_GetItem(cached, 3), 1) &&
      attr_matches(value, s_dtype, PyTuple_GetItem(cached, 4), 1) &&
      attr_matches(value, s_device, PyTuple_GetItem(cached, 5), 1)) {
    PyObject* elem = PyTuple_GetItem(cached, 6);
    PyObject* ndim = PyTuple_GetItem(cached, 7);
    PyObject* dev = PyTuple_GetItem(cached, 8);
    PyObject* f = PyTuple_GetItem(cached, 10);
    long nd = PyLong_Check(ndim) ? PyLong_AsLong(ndim) : -1;
    if (nd == -1 && PyErr_Occurred()) PyErr_Clear();
    if ((p->elem_text == NULL || equal(elem, p->elem_text)) && nd == p->ndim && equal(dev, device) && PyBytes_Check(f)) {
      Py_INCREF(f);
      field = f;
    }
  }
  Py_DECREF(cached);
  return field;
}

/* Writes parameter `p`'s LaunchCommand.args field for scalar `value` into `out` (at most 14
 * bytes); returns its length, or 0 when the Python path must pack it (no error set). */
static size_t scalar_field(PyObject* value, const ParamSpec* p, char* out) {
  char raw[8];
  size_t n = 0;
  if (p->kind == kFloat32 || p->kind == kFloat64) {
    if (!PyFloat_CheckExact(value) && !PyLong_CheckExact(value)) return 0;
    double x = PyFloat_AsDouble(value);
    if (x == -1.0 && PyErr_Occurred()) {
      PyErr_Clear(); /* an int too large for a float: the Python path raises or converts */
      return 0;
    }
    if (p->kind == kFloat64) {
      memcpy(raw, &x, 8);
      n = 8;
    } else {
      if (isnan(x)) return 0; /* struct keeps a NaN's bits its own way */
      float y = (float)x;
      if (isinf(y) && !isinf(x)) return 0; /* struct's OverflowError: the Python path */
      memcpy(raw, &y, 4);
      n = 4;
    }
  } else if (p->kind == kInt) {
    if (!PyLong_CheckExact(value)) return 0; /* bool, NumPy ints: the Python path */
    if (p->is_unsigned64) {
      unsigned long long u = PyLong_AsUnsignedLongLong(value);
      if (u == (unsigned long long)-1 && PyErr_Occurred()) {
        PyErr_Clear();
        return 0;
      }
      memcpy(raw, &u, 8);
    } else {
      int overflow = 0;
      long long v = PyLong_AsLongLongAndOverflow(value, &overflow);
      if (overflow || (v == -1 && PyErr_Occurred())) {
        PyErr_Clear();
        return 0;
      }
      if (v < p->lo || v > p->hi) return 0;
      memcpy(raw, &v, 8); /* little-endian: the low `size` bytes are the value */
    }
    n = (size_t)p->size;
  } else {
    return 0;
  }
  /* args field: tag, length, ArgValue{raw: tag, length, bytes} */
  out[0] = (char)kLaunchArgs;
  out[1] = (char)(n + 2);
  out[2] = (char)kArgRaw;
  out[3] = (char)n;
  memcpy(out + 4, raw, n);
  return n + 4;
}

#define kMaxDims 8
#define kStackParams 32

/* frame(spec, dims, args, device, origin_field) -> bytes or None. */
static PyObject* frame(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  if (argc != 5) {
    PyErr_SetString(PyExc_TypeError, "frame(spec, dims, args, device, origin_field)");
    return NULL;
  }
  if (!g_array_type) Py_RETURN_NONE;
  LaunchSpec* spec = (LaunchSpec*)PyCapsule_GetPointer(argv[0], kCapsuleName);
  if (!spec) return NULL;
  PyObject *dims = argv[1], *args = argv[2], *device = argv[3], *origin = argv[4];
  if (!PyList_Check(dims) || !PyList_Check(args) || !PyBytes_Check(origin) || !PyUnicode_Check(device))
    Py_RETURN_NONE;
  /* dims: 1..8 non-negative ints, as a packed repeated int64 */
  Py_ssize_t ndims = PyList_Size(dims);
  if (ndims < 1 || ndims > kMaxDims) Py_RETURN_NONE;
  char dim_bytes[kMaxDims * 10];
  char* d = dim_bytes;
  for (Py_ssize_t i = 0; i < ndims; ++i) {
    PyObject* item = PyList_GetItem(dims, i);
    if (!PyLong_CheckExact(item)) Py_RETURN_NONE;
    long long v = PyLong_AsLongLong(item);
    if (v < 0) {
      PyErr_Clear();
      Py_RETURN_NONE;
    }
    d = put_varint(d, (uint64_t)v);
  }
  const size_t dim_len = (size_t)(d - dim_bytes);

  const Py_ssize_t n = spec->n;
  if (PyList_Size(args) != n) Py_RETURN_NONE;
  /* Each argument's field: an array's cached bytes (held) or a scalar's bytes in `scratch`. */
  PyObject* held_stack[kStackParams];
  char scratch_stack[kStackParams][16];
  size_t len_stack[kStackParams];
  PyObject** held = held_stack;
  char(*scratch)[16] = scratch_stack;
  size_t* lens = len_stack;
  if (n > kStackParams) {
    held = (PyObject**)PyMem_Calloc((size_t)n, sizeof(PyObject*));
    scratch = (char(*)[16])PyMem_Malloc((size_t)n * 16);
    lens = (size_t*)PyMem_Malloc((size_t)n * sizeof(size_t));
    if (!held || !scratch || !lens) {
      PyMem_Free(held);
      PyMem_Free(scratch);
      PyMem_Free(lens);
      return PyErr_NoMemory();
    }
  } else {
    memset(held_stack, 0, sizeof(held_stack));
  }
  PyObject* result = NULL;
  int fallback = 0;
  size_t fields_len = 0;
  for (Py_ssize_t i = 0; i < n && !fallback; ++i) {
    PyObject* value = PyList_GetItem(args, i);
    if (!value) {
      PyErr_Clear();
      fallback = 1;
      break;
    }
    Py_INCREF(value); /* attribute reads below may run Python code */
    const ParamSpec* p = &spec->params[i];
    if (p->kind == kArray && (PyObject*)Py_TYPE(value) == g_ctype_type) {
      /* an array's ctypes descriptor (from_torch(return_ctype=True)): the array it describes
       * takes its place in `args`, as _pack_fast resolves it; anything else: the Python path */
      PyObject* owner = PyObject_GetAttr(value, s_weft_value);
      int is_array = owner ? PyObject_IsInstance(owner, g_array_type) : 0;
      if (is_array < 0 || !owner) PyErr_Clear();
      if (is_array > 0 && i < PyList_Size(args) && PyList_GetItem(args, i) == value) {
        Py_INCREF(owner);
        PyList_SetItem(args, i, owner); /* steals the reference; `value` is still held */
        Py_DECREF(value);
        value = owner;                  /* our reference, from GetAttr */
      } else {
        Py_XDECREF(owner);
        Py_DECREF(value);
        fallback = 1;
        break;
      }
    }
    if (p->kind == kArray) {
      held[i] = array_field(value, p, device);
      if (held[i]) {
        lens[i] = (size_t)PyBytes_Size(held[i]);
      } else {
        fallback = 1;
      }
    } else {
      lens[i] = scalar_field(value, p, scratch[i]);
      if (lens[i] == 0) fallback = 1;
    }
    Py_DECREF(value);
    fields_len += fallback ? 0 : lens[i];
  }
  if (!fallback) {
    const Py_ssize_t template_len = PyBytes_Size(spec->template_bytes);
    const size_t body_len = (size_t)template_len + 1 + varint_len(dim_len) + dim_len + fields_len;
    const size_t inner_len = 1 + varint_len(body_len) + body_len + (size_t)PyBytes_Size(origin);
    const size_t total = 1 + varint_len(inner_len) + inner_len;
    result = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)total);
    if (result) {
      char* out = PyBytes_AsString(result);
      *out++ = (char)kSubmitCommands;
      out = put_varint(out, inner_len);
      *out++ = (char)kCommandLaunch;
      out = put_varint(out, body_len);
      memcpy(out, PyBytes_AsString(spec->template_bytes), (size_t)template_len);
      out += template_len;
      *out++ = (char)kLaunchDim;
      out = put_varint(out, dim_len);
      memcpy(out, dim_bytes, dim_len);
      out += dim_len;
      for (Py_ssize_t i = 0; i < n; ++i) {
        memcpy(out, held[i] ? PyBytes_AsString(held[i]) : scratch[i], lens[i]);
        out += lens[i];
      }
      memcpy(out, PyBytes_AsString(origin), (size_t)PyBytes_Size(origin));
    }
  }
  for (Py_ssize_t i = 0; i < n; ++i) Py_XDECREF(held[i]);
  if (held != held_stack) {
    PyMem_Free(held);
    PyMem_Free(scratch);
    PyMem_Free(lens);
  }
  if (fallback) Py_RETURN_NONE;
  return result;
}

static PyMethodDef kMethods[] = {
    {"configure", configure, METH_VARARGS,
     "configure(array_type, ctype_type, ref_attr): weft.array.array, weft.array.array_t and the "
     "attribute name of an array's cached launch field."},
    {"spec", make_spec, METH_VARARGS,
     "spec(template_bytes, params) -> capsule: a kernel's launch plan as frame() reads it."},
    {"frame", (PyCFunction)(void (*)(void))frame, METH_FASTCALL,
     "frame(spec, dims, args, device, origin_field) -> the framed launch command, or None when "
     "an argument needs the Python path."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kModule = {
    PyModuleDef_HEAD_INIT, "weft._launch_frame",
    "The launch command of wp.launch's common case, built in C (clients/python/native/launch_frame.c).", -1,
    kMethods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__launch_frame(void) {
  s_dict = PyUnicode_InternFromString("__dict__");
  s_mirror = PyUnicode_InternFromString("_mirror");
  s_handle = PyUnicode_InternFromString("_handle");
  s_byte_offset = PyUnicode_InternFromString("_byte_offset");
  s_shape = PyUnicode_InternFromString("shape");
  s_strides = PyUnicode_InternFromString("strides");
  s_dtype = PyUnicode_InternFromString("dtype");
  s_device = PyUnicode_InternFromString("device");
  s_weft_value = PyUnicode_InternFromString("_weft_value");
  if (!s_dict || !s_mirror || !s_handle || !s_byte_offset || !s_shape || !s_strides || !s_dtype || !s_device ||
      !s_weft_value)
    return NULL;
  return PyModule_Create(&kModule);
}
