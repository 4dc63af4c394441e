// Parser against CPython: programs of the kernel subset (random, and mutations of a real kernel)
// whose expected trees were produced once by CPython's `ast` module and printed in weft's AST
// dump format (docs/language.md); "" means CPython rejects the source, so weft must too.
// Generated with CPython 3.11 (random programs from the subset's grammar, plus random character
// edits of a kernel); frozen data, never edit by hand. Accepting the corpus means weft builds
// CPython's tree, operator for operator, for every case.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "engine/lang/ast_printer.h"
#include "engine/lang/parser.h"

namespace weft::lang {
namespace {

struct CorpusCase {
  const char* source;
  const char* cpython_tree;  // "" = CPython reports a SyntaxError
};

const CorpusCase kCorpus[] = {
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    pass
    y.x = n > b.vec3 < y.vec3 == y.vec3 + a.vec3 & wp
    for i, j in range(i >> True.vec3):
        break
        i //= - - wp
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  pass
  assign (. y x) = (cmp n > (. b vec3) < (. y vec3) == (& (+ (. y vec3) (. a vec3)) wp))
  for (tuple i j) in (call range (>> i (. True vec3)))
    break
    augassign i //= (u- (u- wp))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    2.
    y, i = 's' > i is not 1e-3 & - - y.x + n.x + 'a' 'b'.x.x or - True
    y = i.shape and 1.5 >> .25 @ x or (10000000000000000000000000 + a)(i // b, k=a if n else True)
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  expr 2.0
  assign (tuple y i) = (or (cmp "s" > i is not (& 0.001 (+ (+ (u- (u- (. y x))) (. n x)) (. (. "ab" x) x)))) (u- True))
  assign y = (or (and (. i shape) (>> 1.5 (@ 0.25 x))) (call (+ 10000000000000000000000000 a) (// i b) k=(? n a True)))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a, wp = y > n.x <= 'a' 'b'[n, x, 1].shape and y.vec3
    wp.x %= b | wp.shape @ n if 3.0e+2 else n.shape
    assert 'a' 'b' != 1.5 @ i ** n, "msg"
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple a wp) = (and (cmp y > (. n x) <= (. ([] "ab" n x 1) shape)) (. y vec3))
  augassign (. wp x) %= (? 300.0 (| b (@ (. wp shape) n)) (. n shape))
  assert (cmp "ab" != (@ 1.5 (** i n))), "msg"
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a.x = y & i.vec3.vec3 >= 2.[1_000, ::wp.shape].vec3 ** + 1_000 not in y.vec3 in wp.vec3
    assert False ** b @ 1.5, "msg"
    while True[y, :b:, wp].x / 3.0e+2 * b:
        if - - 10000000000000000000000000(a.vec3, False.x, dtype="%d\n").shape:
            n = []
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (. a x) = (cmp (& y (. (. i vec3) vec3)) >= (** (. ([] 2.0 1000 (: _ _ (. wp shape))) vec3) (u+ 1000)) not in (. y vec3) in (. wp vec3))
  assert (@ (** False b) 1.5), "msg"
  while (* (/ (. ([] True y (: _ b _) wp) x) 300.0) b)
    if (u- (u- (. (call 10000000000000000000000000 (. a vec3) (. False x) dtype="%d\n") shape)))
      assign n = (list)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    for i in range(wp if 'a' 'b'.x else wp):
        x = 1; y = 2
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  for i in (call range (? (. "ab" x) wp wp))
    assign x = 1
    assign y = 2
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    y, a = a.x = []
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple y a) = (. a x) = (list)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    assert 42 and n | i[n]
    b[x if wp else .25] = a = (i).vec3 <= b >= + x
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assert (and 42 (| n ([] i n)))
  assign ([] b (? wp x 0.25)) = a = (cmp (. i vec3) <= b >= (u+ x))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a.x = - - wp if 0o17 else b >> .25.vec3 if 0 else x
    assert False if True else x / n * b.vec3, "msg"
    y.x %= (i[n, wp], 1e-3.vec3(dtype=b))().x
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (. a x) = (? 15 (u- (u- wp)) (? 0 (>> b (. 0.25 vec3)) x))
  assert (? True False (* (/ x n) (. b vec3))), "msg"
  augassign (. y x) %= (. (call (tuple ([] i n wp) (call (. 0.001 vec3) dtype=b))) x)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    y = x
    x.x = y, n = i(dtype=(i))(0b101.vec3 and y.x)
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign y = x
  assign (. x x) = (tuple y n) = (call (call i dtype=i) (and (. 5 vec3) (. y x)))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    wp, wp = y - b & a * 10000000000000000000000000 if x.x else wp if i != a else + y.shape
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple wp wp) = (? (. x x) (& (- y b) (* a 10000000000000000000000000)) (? (cmp i != a) wp (u+ (. y shape))))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x: wp.vec3
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  annassign x: (. wp vec3)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    i.shape
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  expr (. i shape)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x, n = 42
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple x n) = 42
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x = 1; y = 2
    y &= (n % wp.vec3, a and b)("%d\n" ** i.shape)
    a: float
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign x = 1
  assign y = 2
  augassign y &= (call (tuple (% n (. wp vec3)) (and a b)) (** "%d\n" (. i shape)))
  annassign a: float
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x = 1; y = 2
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign x = 1
  assign y = 2
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    i: wp.vec3
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  annassign i: (. wp vec3)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x = 1; y = 2
    x = 1; y = 2
    for i, j in range(wp.x and 1e-3):
        if ~ 0 + x[b, i.x:42:y, 's']():
            i: wp.array(dtype=float)
            a, y = ~ b / x @ (wp if None else x, i.vec3.shape)
        elif x.vec3 >= i & i % x:
            return a, b
        a **= a.vec3['s']
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign x = 1
  assign y = 2
  assign x = 1
  assign y = 2
  for (tuple i j) in (call range (and (. wp x) 0.001))
    if (+ (~ 0) (call ([] x b (: (. i x) 42 y) "s")))
      annassign i: (call (. wp array) dtype=float)
      assign (tuple a y) = (@ (/ (~ b) x) (tuple (? None wp x) (. (. i vec3) shape)))
    elif (cmp (. x vec3) >= (& i (% i x)))
      return (tuple a b)
    augassign a **= ([] (. a vec3) "s")
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    i = + "%d\n".x.vec3 if y * x.x else a @ b // y(k=y.vec3)
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign i = (? (* y (. x x)) (u+ (. (. "%d\n" x) vec3)) (// (@ a b) (call y k=(. y vec3))))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a = - wp >> wp & 42 ** 's'
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign a = (& (>> (u- wp) wp) (** 42 "s"))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a: wp.array(dtype=float) = [n.vec3] if 2. and 127 else b(x, b, dtype=i)
    for i in range(wp != 3.0e+2.shape):
        break
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  annassign a: (call (. wp array) dtype=float) = (? (and 2.0 127) (list (. n vec3)) (call b x b dtype=i))
  for i in (call range (cmp wp != (. 300.0 shape)))
    break
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x = 1; y = 2
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign x = 1
  assign y = 2
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    n[b.x or x] *= [a - i.vec3, (0b101, 's')[wp.x, :y.vec3:x](k=True.vec3.shape)].vec3[(i)[y.vec3, ::](1.5)]
    wp[(b).shape] = ((a.shape in a).x, i ^ wp @ 's'('a' 'b'.shape.x)(x))[0, (1e-3(x, k="%d\n"), a + b.shape)[y - 1, "%d\n".vec3 >= 0x1F > 'a' 'b'.x.vec3]]
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  augassign ([] n (or (. b x) x)) *= ([] (. (list (- a (. i vec3)) (call ([] (tuple 5 "s") (. wp x) (: _ (. y vec3) x)) k=(. (. True vec3) shape))) vec3) (call ([] i (. y vec3) (: _ _ _)) 1.5))
  assign ([] wp (. b shape)) = ([] (tuple (. (cmp (. a shape) in a) x) (^ i (@ wp (call (call "s" (. (. "ab" shape) x)) x)))) 0 ([] (tuple (call 0.001 x k="%d\n") (+ a (. b shape))) (- y 1) (cmp (. "%d\n" vec3) >= 31 > (. (. "ab" x) vec3))))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    wp.x = not  [not  0b101, 1 is not n.shape]
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (. wp x) = (not (list (not 5) (cmp 1 is not (. n shape))))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    n[None] = b.x >> y @ y + y[127, n][42] != n * b == a ** x
    while (False.shape) % x.x // 1:
        i = x and wp or x + wp if 'a' 'b' >> b.shape.x >= 's' != b > x else not  0 in 127 == 0o17
        b = y = + b * a
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign ([] n None) = (cmp (>> (. b x) (+ (@ y y) ([] ([] y 127 n) 42))) != (* n b) == (** a x))
  while (// (% (. False shape) (. x x)) 1)
    assign i = (? (cmp (>> "ab" (. (. b shape) x)) >= "s" != b > x) (or (and x wp) (+ x wp)) (not (cmp 0 in 127 == 15)))
    assign b = y = (* (u+ b) a)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x.x = [0[a](dtype=i) if ~ 0o17.vec3 else 0b101.vec3, + 2. % 127](not  b ^ y % b, - - n + n).x
    x[x.vec3.shape] = False[wp.shape % i::][:wp if a.x.x else y:b or n] % y // wp >= a.x or "%d\n"
    y[wp.x ^ b.shape] = not  x.x % a.vec3 // True
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (. x x) = (. (call (list (? (~ (. 15 vec3)) (call ([] 0 a) dtype=i) (. 5 vec3)) (% (u+ 2.0) 127)) (not (^ b (% y b))) (+ (u- (u- n)) n)) x)
  assign ([] x (. (. x vec3) shape)) = (or (cmp (// (% ([] ([] False (: (% (. wp shape) i) _ _)) (: _ (? (. (. a x) x) wp y) (or b n))) y) wp) >= (. a x)) "%d\n")
  assign ([] y (^ (. wp x) (. b shape))) = (not (// (% (. x x) (. a vec3)) True))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    a = - b or 1e-3 | 0 >= 1_000 not in 0b101
    None[b, x.vec3 or x.x.vec3, wp.x.x if n.vec3.vec3 else "%d\n".shape](a.x and i, b - wp.shape)
    y.x = + n
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign a = (or (u- b) (cmp (| 0.001 0) >= 1000 not in 5))
  expr (call ([] None b (or (. x vec3) (. (. x x) vec3)) (? (. (. n vec3) vec3) (. (. wp x) x) (. "%d\n" shape))) (and (. a x) i) (- b (. wp shape)))
  assign (. y x) = (u+ n)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    if 10000000000000000000000000:
        assert [1_000 or y, 'a' 'b' >> y.vec3][wp.vec3, (n, n.x), n.vec3.vec3 ^ y]
        while n.vec3 if None else n - 1e-3.shape or y:
            return a, b
            a: wp.vec3 = y
    else:
        i
    assert - - x / "%d\n" / x, "msg"
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  if 10000000000000000000000000
    assert ([] (list (or 1000 y) (>> "ab" (. y vec3))) (. wp vec3) (tuple n (. n x)) (^ (. (. n vec3) vec3) y))
    while (? None (. n vec3) (or (- n (. 0.001 shape)) y))
      return (tuple a b)
      annassign a: (. wp vec3) = y
  else
    expr i
  assert (/ (/ (u- (u- x)) "%d\n") x), "msg"
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    while n(False << 's', x):
        y, x = y.vec3(i, k=1) < 0o17 if a else wp not in n * b >> 0x1F.vec3 % wp.x is not i[wp, a, .25.x].shape
    x: float
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  while (call n (<< False "s") x)
    assign (tuple y x) = (? a (cmp (call (. y vec3) i k=1) < 15) (cmp wp not in (>> (* n b) (% (. 31 vec3) (. wp x))) is not (. ([] i wp a (. 0.25 x)) shape)))
  annassign x: float
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    y = i.x = x.x + i == True > y is y.shape
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign y = (. i x) = (cmp (+ (. x x) i) == True > y is (. y shape))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    assert 0 << 127 if n.x else wp[::y].vec3, "msg"
    b, b = wp.shape(3.0e+2, not  x if y else n)
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assert (? (. n x) (<< 0 127) (. ([] wp (: _ _ y)) vec3)), "msg"
  assign (tuple b b) = (call (. wp shape) 300.0 (? y (not x) n))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    n.x = - y < x < "%d\n".shape % 1_000 * n
    i, b = wp, b = - - n + 42
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (. n x) = (cmp (u- y) < x < (* (% (. "%d\n" shape) 1000) n))
  assign (tuple i b) = (tuple wp b) = (+ (u- (u- n)) 42)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x, a = i[x not in b] = a >> None >> 2..shape(b, k=b)
    b, i = 0
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple x a) = ([] i (cmp x not in b)) = (>> (>> a None) (call (. 2.0 shape) b k=b))
  assign (tuple b i) = 0
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    wp, i = [not  (a, n.vec3)(i)[n]]
    y: wp.array(dtype=float)
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign (tuple wp i) = (list (not ([] (call (tuple a (. n vec3)) i) n)))
  annassign y: (call (. wp array) dtype=float)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    assert x.x, "msg"
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assert (. x x), "msg"
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    b.x |= False[False >= b.shape]
    a.x = a
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  augassign (. b x) |= ([] False (cmp False >= (. b shape)))
  assign (. a x) = a
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    (b + x.vec3, i.x - y).vec3
    wp.x = y // 3.0e+2 << None['a' 'b', b] or + y.x | 1.5
    b, i = b = [[1e-3.shape](b.shape, 1e-3, k=y.x).x]
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  expr (. (tuple (+ b (. x vec3)) (- (. i x) y)) vec3)
  assign (. wp x) = (or (<< (// y 300.0) ([] None "ab" b)) (| (u+ (. y x)) 1.5))
  assign (tuple b i) = b = (list (. (call (list (. 0.001 shape)) (. b shape) 0.001 k=(. y x)) x))
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    while 0b101 * n and b:
        y, wp = (y(["%d\n"], dtype=3.0e+2)[n.vec3 is not n, n & a])('a' 'b'[not  x, i if True else True.x.x, 's' is a.vec3].x)[::, None.shape]
        continue
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  while (and (* 5 n) b)
    assign (tuple y wp) = ([] (call ([] (call y (list "%d\n") dtype=300.0) (cmp (. n vec3) is not n) (& n a)) (. ([] "ab" (not x) (? True i (. (. True x) x)) (cmp "s" is (. a vec3))) x)) (: _ _ _) (. None shape))
    continue
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    return a, b
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  return (tuple a b)
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    n[[x, i]] = (127(wp.x, wp.vec3, dtype=x).x).vec3.vec3 >> n @ i.x.vec3 / "%d\n"
    x = 1; y = 2
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign ([] n (list x i)) = (>> (. (. (. (call 127 (. wp x) (. wp vec3) dtype=x) x) vec3) vec3) (/ (@ n (. (. i x) vec3)) "%d\n"))
  assign x = 1
  assign y = 2
)py"},
    {R"py(def f(a: float, b: wp.array(dtype=wp.vec3), n: int = 3) -> float:
    x = 1; y = 2
    .25
    y.x <<= x - a if - - a.vec3 else n.vec3 | b.x
)py",
     R"py(def f(a: float, b: (call (. wp array) dtype=(. wp vec3)), n: int = 3) -> float
  assign x = 1
  assign y = 2
  expr 0.25
  augassign (. y x) <<= (? (u- (u- (. a vec3))) (- x a) (| (. n vec3) (. b x)))
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, 1j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += o2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
 i      a[i] += 2.0 ** -b[i, j].x if n elsee0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n',
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n:  = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in rge(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call rge 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.a9ray(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for@ q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.arrayo(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
       a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp arrayo) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -@b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 **; -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float),"b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x i] n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[ic, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b ic j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        whil-e q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and no] j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def(a: wp.array(dt<ype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=floa b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif         wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    _elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; conti9nue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
"   """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue+
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    c"""doc"""
    i, j = wp.tid()}
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    r.turn
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  expr (. r turn)
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif /:
        wp.printf('%d\n'l i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    "oc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
     "      q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n:l int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.ti=()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (. wp ti) = (tuple)
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3)"
    """doc"""
>   i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if ) < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.drray(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    rurn
)py",
     R"py(def k(a: (call (. wp drray) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  expr rurn
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:(
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.arra2d[wp.vec3], n: int = 3):
 #   """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp arra2d) (. wp vec3)), n: int = 3)
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n d not j >= 2:
        a[{] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py()py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.arry2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp arry2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; con+tinue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      expr (+ con tinue)
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
     wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, o2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n o2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: w9.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. w9 array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.vec3], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        w.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp vec3)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. w printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
    {R"py(def k(a: wp.array(dtype=float), b: wp.array2d[wp.ve], n: int = 3):
    """doc"""
    i, j = wp.tid()
    if i < n and not j >= 2:
        a[i] += 2.0 ** -b[i, j].x if n else 0x1F
    elif i:
        wp.printf('%d\n', i)
    for q in range(0, n, 2):
        while q > 0:
            q -= 1; continue
    return
)py",
     R"py(def k(a: (call (. wp array) dtype=float), b: ([] (. wp array2d) (. wp ve)), n: int = 3)
  doc "doc"
  assign (tuple i j) = (call (. wp tid))
  if (and (cmp i < n) (not (cmp j >= 2)))
    augassign ([] a i) += (? n (** 2.0 (u- (. ([] b i j) x))) 31)
  elif i
    expr (call (. wp printf) "%d\n" i)
  for q in (call range 0 n 2)
    while (cmp q > 0)
      augassign q -= 1
      continue
  return
)py"},
};

TEST(LangCpythonCorpus, TreesAndRejectionsMatchCpython) {
  int accepted = 0, rejected = 0;
  for (const CorpusCase& c : kCorpus) {
    FunctionSource fn;
    fn.file = "corpus.py";
    fn.source = c.source;
    std::vector<Diagnostic> diags;
    auto r = ParseFunction(fn, &diags);
    const std::string want = c.cpython_tree;
    if (want.empty()) {
      EXPECT_FALSE(r.ok()) << "CPython rejects but weft accepts:\n" << c.source;
      EXPECT_EQ(diags.size(), 1u) << c.source;
      ++rejected;
    } else {
      ASSERT_TRUE(r.ok()) << c.source << "\n" << r.status().ToString();
      EXPECT_EQ(PrintFunction(**r), want) << c.source;
      ++accepted;
    }
  }
  EXPECT_GE(accepted, 50);
  EXPECT_GE(rejected, 20);
}

}  // namespace
}  // namespace weft::lang
