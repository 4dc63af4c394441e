/* weft._torch_descriptor: wp.from_torch(t, return_ctype=True) of a tensor converted before, in
 * C. The rule is the Python one (weft/interop/torch.py: _last_descriptor, _remembered, _plain),
 * checked in the same order; this file owns only doing it without the interpreter's per-step
 * cost, since a loop converting the same tensors pays it five times per launch.
 *
 * remembered(t, dtype, requires_grad, get_runtime) -> a copy of the descriptor remembered on
 * tensor `t`, or None (the caller then converts in Python). The descriptor is remembered in
 * t.__dict__["_weft_last_ctype"] as (last, desc, name): `last` = (key, array) is the conversion
 * it was made from, remembered under t.__dict__[name] ("_weft_last_import" for a CUDA import,
 * "_weft_cpu_array" for a CPU slab array). A copy is returned only when
 *   - t.__dict__[name] is still `last`;
 *   - no gradient is asked for (`requires_grad`, else t.requires_grad, is false);
 *   - key == (t.data_ptr(), t.shape, t.stride(), t.dtype, dtype): the tensor is unchanged;
 *   - the array's session is open (array._alloc.runtime.closed is false) and, for a CUDA import,
 *     is the current one (`get_runtime()`);
 *   - the array has neither a gradient nor a flag (_grad is None, _info.grad_handle and
 *     _retain_grad false).
 * The copy is type(desc).from_buffer_copy(desc) with `_weft_value` set to desc's. Anything
 * unexpected (a missing attribute, an entry of another shape, an exception raised by the
 * tensor) returns None with the error cleared: the Python path then does the conversion and
 * reports what is wrong. */
#define PY_SSIZE_T_CLEAN
#define Py_LIMITED_API 0x030A0000
#include <Python.h>

static PyObject *s_dict, *s_last_ctype, *s_last_import, *s_requires_grad, *s_data_ptr, *s_shape, *s_stride,
    *s_dtype, *s_alloc, *s_runtime, *s_closed, *s_grad, *s_info, *s_grad_handle, *s_retain_grad, *s_from_buffer_copy,
    *s_weft_value;

/* 1 / 0 for a true / false attribute `name` of `obj`, -1 on an error. */
static int attr_truth(PyObject* obj, PyObject* name) {
  PyObject* v = PyObject_GetAttr(obj, name);
  if (v == NULL) return -1;
  int truth = PyObject_IsTrue(v);
  Py_DECREF(v);
  return truth;
}

/* Whether `t` is unchanged since `key` was taken: 1 / 0, -1 on an error. */
static int key_holds(PyObject* t, PyObject* key, PyObject* dtype) {
  PyObject* ptr = PyObject_CallMethodObjArgs(t, s_data_ptr, NULL);
  PyObject* shape = ptr ? PyObject_GetAttr(t, s_shape) : NULL;
  PyObject* stride = shape ? PyObject_CallMethodObjArgs(t, s_stride, NULL) : NULL;
  PyObject* dt = stride ? PyObject_GetAttr(t, s_dtype) : NULL;
  PyObject* now = dt ? PyTuple_Pack(5, ptr, shape, stride, dt, dtype) : NULL;
  Py_XDECREF(ptr);
  Py_XDECREF(shape);
  Py_XDECREF(stride);
  Py_XDECREF(dt);
  if (now == NULL) return -1;
  int same = PyObject_RichCompareBool(key, now, Py_EQ);
  Py_DECREF(now);
  return same;
}

/* The whole rule; a new reference to the copy, Py_None (new reference) for a miss, NULL on an
 * error (the caller clears it and answers None). */
static PyObject* lookup(PyObject* t, PyObject* dtype, PyObject* requires_grad, PyObject* get_runtime) {
  PyObject* result = NULL;
  PyObject *d = NULL, *entry = NULL, *alloc = NULL, *rt = NULL, *info = NULL, *current = NULL;
  d = PyObject_GetAttr(t, s_dict);
  if (d == NULL || !PyDict_Check(d)) goto miss;
  /* Held for the whole look-up: the tensor's own code (requires_grad, data_ptr, ...) may
   * replace the entry in its __dict__, and the tuple keeps what is read from it alive. */
  entry = PyDict_GetItemWithError(d, s_last_ctype);
  Py_XINCREF(entry);
  if (entry == NULL || !PyTuple_Check(entry) || PyTuple_Size(entry) != 3) goto miss;
  PyObject* last = PyTuple_GetItem(entry, 0);
  PyObject* desc = PyTuple_GetItem(entry, 1);
  PyObject* name = PyTuple_GetItem(entry, 2);
  if (!PyUnicode_Check(name)) goto miss;
  if (PyDict_GetItemWithError(d, name) != last) goto miss;
  int wants_grad = requires_grad != Py_None ? PyObject_IsTrue(requires_grad) : attr_truth(t, s_requires_grad);
  if (wants_grad != 0) goto miss;
  if (!PyTuple_Check(last) || PyTuple_Size(last) != 2) goto miss;
  PyObject* key = PyTuple_GetItem(last, 0);
  PyObject* known = PyTuple_GetItem(last, 1);
  if (key_holds(t, key, dtype) != 1) goto miss;
  alloc = PyObject_GetAttr(known, s_alloc);
  if (alloc == NULL) goto miss;
  rt = PyObject_GetAttr(alloc, s_runtime);
  if (rt == NULL || attr_truth(rt, s_closed) != 0) goto miss;
  int cuda = PyUnicode_Compare(name, s_last_import);
  if (cuda == -1 && PyErr_Occurred()) goto miss;
  if (cuda == 0) { /* a CUDA import: of the current session only */
    current = PyObject_CallNoArgs(get_runtime);
    if (current != rt) goto miss;
  }
  PyObject* grad = PyObject_GetAttr(known, s_grad);
  if (grad == NULL) goto miss;
  int has_grad = grad != Py_None;
  Py_DECREF(grad);
  if (has_grad) goto miss;
  info = PyObject_GetAttr(known, s_info);
  if (info == NULL || attr_truth(info, s_grad_handle) != 0 || attr_truth(known, s_retain_grad) != 0) goto miss;
  PyObject* copy = PyObject_CallMethodObjArgs((PyObject*)Py_TYPE(desc), s_from_buffer_copy, desc, NULL);
  if (copy == NULL) goto miss;
  PyObject* owner = PyObject_GetAttr(desc, s_weft_value);
  if (owner == NULL || PyObject_SetAttr(copy, s_weft_value, owner) != 0) {
    Py_XDECREF(owner);
    Py_DECREF(copy);
    goto miss;
  }
  Py_DECREF(owner);
  result = copy;
  goto done;
miss:
  if (!PyErr_Occurred()) result = Py_NewRef(Py_None);
done:
  Py_XDECREF(d);
  Py_XDECREF(entry);
  Py_XDECREF(alloc);
  Py_XDECREF(rt);
  Py_XDECREF(info);
  Py_XDECREF(current);
  return result;
}

static PyObject* remembered(PyObject* self, PyObject* const* argv, Py_ssize_t argc) {
  if (argc != 4) {
    PyErr_SetString(PyExc_TypeError, "remembered(t, dtype, requires_grad, get_runtime)");
    return NULL;
  }
  if (!PyCallable_Check(argv[3])) {
    PyErr_SetString(PyExc_TypeError, "remembered: get_runtime must be callable");
    return NULL;
  }
  PyObject* out = lookup(argv[0], argv[1], argv[2], argv[3]);
  if (out == NULL) {
    PyErr_Clear(); /* the Python path converts and reports */
    Py_RETURN_NONE;
  }
  return out;
}

static PyMethodDef kMethods[] = {
    {"remembered", (PyCFunction)(void (*)(void))remembered, METH_FASTCALL,
     "remembered(t, dtype, requires_grad, get_runtime) -> a copy of the descriptor remembered on "
     "tensor t while it still holds, else None."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kModule = {
    PyModuleDef_HEAD_INIT, "weft._torch_descriptor",
    "wp.from_torch(t, return_ctype=True) of a tensor converted before, in C "
    "(clients/python/native/torch_descriptor.c).",
    -1, kMethods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__torch_descriptor(void) {
  struct {
    PyObject** slot;
    const char* text;
  } names[] = {
      {&s_dict, "__dict__"},         {&s_last_ctype, "_weft_last_ctype"}, {&s_last_import, "_weft_last_import"},
      {&s_requires_grad, "requires_grad"}, {&s_data_ptr, "data_ptr"}, {&s_shape, "shape"},
      {&s_stride, "stride"},         {&s_dtype, "dtype"},                 {&s_alloc, "_alloc"},
      {&s_runtime, "runtime"},       {&s_closed, "closed"},               {&s_grad, "_grad"},
      {&s_info, "_info"},            {&s_grad_handle, "grad_handle"},     {&s_retain_grad, "_retain_grad"},
      {&s_from_buffer_copy, "from_buffer_copy"}, {&s_weft_value, "_weft_value"},
  };
  for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); ++i) {
    *names[i].slot = PyUnicode_InternFromString(names[i].text);
    if (*names[i].slot == NULL) return NULL;
  }
  return PyModule_Create(&kModule);
}
