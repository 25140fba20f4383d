"""The matrix exponential in double-double arithmetic, rounded once to double.

Why: for a stiff scene, ||A h|| is large (1e4 for the 1e6:1 two-mass chain at
h = 0.01 s), and scaling and squaring in double loses about log2 ||A h|| bits of
the slow modes' propagator: scipy's expm gives Phi = expm(A h) with an error of
8e-13, and the slow mode, stepped a thousand times, ends 5e-10 off (and another
CPU's BLAS rounds differently: 3.6e-9). The same algorithm in double-double
(about 32 digits) gives Phi correctly rounded, and stepping it then stays at
rounding level (2e-14 over the same run).

Double-double numbers are pairs (hi, lo) with |lo| <= ulp(hi) / 2, built from
the error-free transformations TwoSum and TwoProd (Dekker's split; no fused
multiply-add needed), vectorized with numpy. Cost: about 30 products of size^2
arrays per column, so it is used only where double precision is not enough
(see `needed`). Imports nothing from smd.

`expm_stack` is the double-precision exponential of many small matrices at once (scipy's expm, Higham's
Pade 13 with scaling and squaring, vectorized over the stack: a 1,000-mode scene's propagators in a few
milliseconds rather than a fifth of a second).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

_SPLIT = 134217729.0  # 2^27 + 1, Dekker's splitting constant
TAYLOR_TERMS = 12  # after scaling to ||B||_1 <= 2^-6: truncation below 1e-33
SCALED_NORM = 2.0**-6
MAX_SIZE = 160  # beyond this the double-double products cost more than the scene is worth
NEEDED_NORM = 16.0  # ||A h||_1 above which double scaling and squaring loses digits worth keeping

_TINY = np.finfo(float).tiny
# an entry this far below the largest of its matrix moves nothing the run states (its accuracy is relative to the
# state's peak, 1e-16 at best); kept, the far corners of a chain's propagator fall below the normal range, and each
# product that meets such an entry costs a hundred times its share (a 63-mass chain's block reads: 26 ms, 8.7
# without them)
_NEGLIGIBLE = 2.0**-400


def flush_negligible(array: np.ndarray) -> np.ndarray:
    """array with every entry below _NEGLIGIBLE (4e-121) of its largest set to zero, in place; array. Subnormal
    numbers slow every product that meets them, and so does a product that underflows: two factors so flushed
    multiply to no less than 1e-241 of their largest, a normal number."""
    magnitude = np.abs(array)
    largest = float(magnitude.max(initial=0.0))
    if largest > 0:
        np.putmask(array, magnitude < max(largest * _NEGLIGIBLE, _TINY), 0.0)
    return array


def propagator(A: np.ndarray, h: float) -> tuple[np.ndarray, float, bool]:
    """(expm(A h), the balanced ||B h||_1, whether it took double-double). A is balanced first (scipy's
    matrix_balance: a diagonal of powers of two, an exact similarity B = D^-1 A D): a scene's displacements and
    velocities in their own units make ||A h||_1 about its squared frequency times h, where its flow grows as the
    frequency (a 20-mass chain under a record: 160 balanced to 1.4), and it is ||B h||_1 that scaling and squaring
    loses digits by. Double-double only where that is past NEEDED_NORM (a stiff scene); on that 20-mass chain the
    double exponential of B is within 2.5e-16 of the double-double one entry by entry (in B's scale), and takes 0.4
    ms instead of 37."""
    from scipy.linalg import expm, matrix_balance

    norm = float(np.abs(A).sum(axis=0).max(initial=0.0)) * h
    if not needed(norm, len(A)):  # small enough as it is: no balancing (a third of a millisecond)
        return expm(A * h), norm, False
    B, (scale, _) = matrix_balance(A, permute=False, separate=True)
    norm = float(np.abs(B).sum(axis=0).max(initial=0.0)) * h
    accurate = needed(norm, len(A))
    E = expm_times(B, h) if accurate else expm(B * h)
    return E * scale[:, None] / scale[None, :], norm, accurate


def needed(norm_Ah: float, size: int) -> bool:
    """Whether double precision's scaling and squaring loses digits here, and the size allows the remedy."""
    return norm_Ah > NEEDED_NORM and size <= MAX_SIZE


def _two_sum(a, b):
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _split(a):
    t = _SPLIT * a
    hi = t - (t - a)
    return hi, a - hi


def _two_prod(a, b):
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _normalize(hi, lo):
    s = hi + lo
    return s, lo - (s - hi)


def _matmul(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]):
    """(ah + al) @ (bh + bl) in double-double: ah @ bh error-free, the cross terms in double."""
    ah, al = a
    bh, bl = b
    s = np.zeros(np.broadcast_shapes(ah.shape[:-2], bh.shape[:-2]) + (ah.shape[-2], bh.shape[-1]))
    c = np.zeros_like(s)
    for k in range(ah.shape[-1]):
        p, e = _two_prod(ah[..., :, k:k + 1], bh[..., k:k + 1, :])
        s, t = _two_sum(s, p)
        c += t + e
    c += ah @ bl + al @ bh
    return _normalize(s, c)


def _add_identity_times(p, coefficient: tuple[float, float]):
    hi, lo = p[0].copy(), p[1].copy()
    d = np.arange(hi.shape[-1])
    s, e = _two_sum(hi[..., d, d], coefficient[0])
    hi[..., d, d], lo[..., d, d] = _normalize(s, lo[..., d, d] + e + coefficient[1])
    return hi, lo


def _inverse_factorial(k: int) -> tuple[float, float]:
    exact = Fraction(1, math.factorial(k))
    hi = float(exact)
    return hi, float(exact - Fraction(hi))


def expm_times(A: np.ndarray, h: float) -> np.ndarray:
    """expm(A h), computed in double-double and rounded to double: Taylor after scaling, then squaring.
    A may be a stack (..., size, size): each is scaled by the largest one's power of two (more squarings than
    a small one needs cost time, not accuracy)."""
    A = np.asarray(A, dtype=float)
    bh, bl = _two_prod(A, np.full_like(A, float(h)))
    norm = np.abs(bh).sum(axis=-2).max(initial=0.0)
    squarings = max(0, math.ceil(math.log2(norm / SCALED_NORM))) if norm > 0 else 0
    scale = 2.0**-squarings  # a power of two: exact
    b = (bh * scale, bl * scale)
    n = A.shape[-1]
    coefficient = _inverse_factorial(TAYLOR_TERMS)
    eye = np.broadcast_to(np.eye(n), A.shape)
    p = (eye * coefficient[0], eye * coefficient[1])
    for k in range(TAYLOR_TERMS - 1, -1, -1):  # Horner: p = b p + I / k!
        p = _add_identity_times(_matmul(b, p), _inverse_factorial(k))
    for _ in range(squarings):
        p = _matmul(p, p)
    return p[0] + p[1]


# Higham (2005): Pade 13 is accurate to unit roundoff for ||A||_1 <= THETA_13, after scaling by 2^-s
PADE_13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
            10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
THETA_13 = 5.371920351148152


def expm_stack(A: np.ndarray) -> np.ndarray:
    """expm of each matrix of a stack (..., size, size) in double: Pade 13 after scaling each by its own power of
    two, then squaring each as often as it was scaled."""
    A = np.asarray(A, dtype=float)
    norms = np.abs(A).sum(axis=-2).max(axis=-1)
    with np.errstate(divide="ignore"):
        squarings = np.maximum(0, np.ceil(np.log2(norms / THETA_13))).astype(int)
    A = A * np.ldexp(1.0, -squarings)[..., None, None]
    b = PADE_13
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye
    E = np.linalg.solve(V - U, V + U)
    for j in range(int(squarings.max(initial=0))):
        more = squarings > j
        E[more] = E[more] @ E[more]
    return E
