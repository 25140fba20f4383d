"""The output rows of a Taylor series integrator (smdcli.kernels.taylor): the series of x, v and a summed at the rows'
times, each to the order its row needs, many sums side by side so that the loops vectorize.

Must not import: solvers, sweep, io, plots, commands, cli.
"""

from __future__ import annotations

from smdcli.kernels.compiler import inlined, no_alloc

ROWS = 16  # output rows summed side by side
# of the step's tolerance: what the terms an output row drops may add up to. The steps' errors add up to far less
# than their tolerance on smooth scenes (the 100-mass chain's run, 1.7e-12 of its peak, is a sixtieth of it): a
# tenth took that run's error to 1.0e-11, a thousandth keeps it.
OUTPUT_SHARE = 0.001


@inlined
def summed(S, first, tau, into, top):
    """The series of components first.. of S (as many as `into` holds), orders 0..top, summed at tau, into `into`:
    two orders at a time over all the components, so the loops vectorize where one component's Horner sum is a chain
    of dependent multiply-adds, and `into` is read and written half as often (the output rows of the 100-mass chain
    20 % faster; the same multiply-adds in the same order, so the same sums)."""
    count = len(into)
    highest = S[top, first:first + count]
    for i in range(count):
        into[i] = highest[i]
    k = top - 1
    while k >= 1:
        # contiguous slices: indexed S[k, i], the loop ran at half the speed
        term, below = S[k, first:first + count], S[k - 1, first:first + count]
        for i in range(count):
            into[i] = (into[i] * tau + term[i]) * tau + below[i]
        k -= 2
    if k == 0:
        term = S[0, first:first + count]
        for i in range(count):
            into[i] = into[i] * tau + term[i]


@inlined
def largest(values):
    """max |values| (0 for none), four running maxima side by side: one is a chain of dependent comparisons (with one,
    the 100-mass chain's kernel took 0.80 ms instead of 0.75, the 1,000-mass chain's 9.1 instead of 8.2)."""
    a, b, c, d = 0.0, 0.0, 0.0, 0.0
    count = len(values)
    whole = count - count % 4
    for i in range(0, whole, 4):
        a = max(a, abs(values[i]))
        b = max(b, abs(values[i + 1]))
        c = max(c, abs(values[i + 2]))
        d = max(d, abs(values[i + 3]))
    for i in range(whole, count):
        a = max(a, abs(values[i]))
    return max(max(a, b), max(c, d))


@inlined
def widen(values, extremes, q):
    """extremes[2q] and [2q + 1], the least and the largest value so far, widened to take in values: four of each
    side by side (one is a chain of dependent comparisons: 0.15 ms for 2,000 rows of 138 values where four take 0.10;
    the loop does not vectorize, fast-math or not). A NaN is not taken in: it needs a NaN term, which the step's state
    has too, and the kernel stops the run there (state_status), where its extremes are not used."""
    l0 = l1 = l2 = l3 = extremes[2 * q]
    h0 = h1 = h2 = h3 = extremes[2 * q + 1]
    count = len(values)
    whole = count - count % 4
    for i in range(0, whole, 4):
        a, b, c, d = values[i], values[i + 1], values[i + 2], values[i + 3]
        l0, h0 = min(l0, a), max(h0, a)
        l1, h1 = min(l1, b), max(h1, b)
        l2, h2 = min(l2, c), max(h2, c)
        l3, h3 = min(l3, d), max(h3, d)
    for i in range(whole, count):
        l0, h0 = min(l0, values[i]), max(h0, values[i])
    extremes[2 * q], extremes[2 * q + 1] = min(min(l0, l1), min(l2, l3)), max(max(h0, h1), max(h2, h3))


@inlined
def read_ahead(out, first, last, lowest, highest):
    """The sum of a value from each cache line of out's blocks that rows first..last-1 write at DOFs lowest..highest-1,
    read before any is written, so that their misses overlap where out is larger than the caches (the 1,000-mass
    chain's 24 MB: its kernel 4 to 9 % faster than with the misses waited on one row at a time; no faster on the
    100-mass chain's 2.4 MB, which skips it). The caller keeps the sum, so that the reads are not dropped."""
    total = 0.0
    for r in range(first, last):
        for q in range(3):
            line = out[q, r]
            for i in range(lowest, highest, 8):
                total += line[i]
    return total


@no_alloc
def order_sizes(Y, sizes, lowest, highest, first, last):
    """The largest |term| of v's orders lowest..highest, and of those of x and a that follow from them: sizes[1, k],
    sizes[0, k] and sizes[2, k] (x's terms are v's over k, a's (k + 1) v_(k+1)); DOFs first..last-1 hold every term
    that is not zero."""
    p = Y.shape[0] - 1
    n = Y.shape[1] // 2
    for k in range(lowest, highest + 1):
        sizes[1, k] = largest(Y[k, n + first:n + last])
    if lowest == 0:
        sizes[0, 0] = largest(Y[0, first:last])
    for k in range(lowest + 1, min(highest + 1, p) + 1):  # x_k = v_(k-1) / k: rounding keeps the largest the largest
        sizes[0, k] = sizes[1, k - 1] * (1.0 / k)
    for k in range(max(lowest - 1, 0), highest):
        sizes[2, k] = (k + 1) * sizes[1, k + 1]
    sizes[2, p] = 0.0


@inlined
def row_order(sizes, q, powers, threshold, top):
    """The lowest order m of quantity q's series (0 x, 1 v, 2 a) whose terms m+1..top, at their largest, add up to at
    most threshold at the row (powers: |tau|^k): what the row needs of the series."""
    tail = 0.0
    m = top
    while m > 0:
        tail += sizes[q, m] * powers[m]
        if tail > threshold:
            break
        m -= 1
    return m


@inlined
def fill_powers(tau, powers):
    """powers[k] = |tau|^k."""
    span = abs(tau)
    power = 1.0
    for k in range(len(powers)):
        powers[k] = power
        power *= span


@inlined
def negligible(S, column, powers, threshold, top):
    """Whether the terms 0..top of S[:, column] add up to at most threshold at their largest (powers: |tau|^k)."""
    total = 0.0
    for k in range(top + 1):
        total += abs(S[k, column]) * powers[k]
    return total <= threshold


@inlined
def significant(Y, A, thresholds, powers, i):
    """Whether DOF i's x, v or a can pass its row threshold at |tau| up to the powers' (see output_span)."""
    n = Y.shape[1] // 2
    p = Y.shape[0] - 1
    return not (negligible(Y, i, powers, thresholds[0], p) and negligible(Y, n + i, powers, thresholds[1], p)
                and negligible(A, i, powers, thresholds[2], p - 1))


@no_alloc
def output_span(Y, A, thresholds, powers, lowest, highest):
    """The DOFs within lowest..highest-1 whose rows can differ from zero by more than the thresholds at |tau| up to
    the powers' (|tau|^k), (low, high + 1): the series' terms reach a few DOFs past the wave, at sizes an output row
    would drop anyway (the 1,000-mass chain's rows: 78 DOFs on average, 67 past the thresholds)."""
    low, high = lowest, highest
    while high > low and not significant(Y, A, thresholds, powers, high - 1):
        high -= 1
    while low < high and not significant(Y, A, thresholds, powers, low):
        low += 1
    return low, high


@no_alloc
def emit_rows(Y, A, sizes, thresholds, powers, t, grid, first, last, out, lowest, highest, zeroed, extremes):
    """Rows first..last-1 of out, a row's components side by side, each quantity summed to the order its row needs,
    over the DOFs within lowest..highest-1 where the rows can pass the thresholds (output_span) and zeros elsewhere,
    as the series' terms are or as the row would drop them (unless out is zeroed already); extremes widened to take
    in the rows' x and v (see emit). Its own function: inlined into emit, the same loops ran 10 % slower than one
    order at a time."""
    n = out.shape[2]
    p = Y.shape[0] - 1
    fill_powers(max(abs(grid[first] - t), abs(grid[last - 1] - t)), powers)
    low, high = output_span(Y, A, thresholds, powers, lowest, highest)
    if low > lowest or high < highest:  # zeros the series did not hold: the extremes take them in
        for q in range(2):
            extremes[2 * q], extremes[2 * q + 1] = min(extremes[2 * q], 0.0), max(extremes[2 * q + 1], 0.0)
    lowest, highest = low, high
    if zeroed:  # out is larger than the caches: the rows' lines fetched together (zeros; a NaN never comes)
        ahead = read_ahead(out, first, last, lowest, highest)
        if ahead != ahead:
            extremes[0] = ahead
    for r in range(first, last):
        tau = grid[r] - t
        fill_powers(tau, powers)
        x, v, a = out[0, r], out[1, r], out[2, r]
        if highest - lowest < n:
            if not zeroed:
                for q in range(3):  # slices, so that the loops' indices start at 0 and vectorize (see summed)
                    before, after = out[q, r, :lowest], out[q, r, highest:]
                    for i in range(len(before)):
                        before[i] = 0.0
                    for i in range(len(after)):
                        after[i] = 0.0
            x, v, a = x[lowest:highest], v[lowest:highest], a[lowest:highest]
        summed(Y, lowest, tau, x, row_order(sizes, 0, powers, thresholds[0], p))
        summed(Y, n + lowest, tau, v, row_order(sizes, 1, powers, thresholds[1], p))
        widen(x, extremes, 0)
        widen(v, extremes, 1)
        summed(A, lowest, tau, a, row_order(sizes, 2, powers, thresholds[2], p - 1))


@no_alloc
def emit(Y, A, sizes, thresholds, powers, t, grid, first, last, out, taus, sums, lowest, highest, zeroed, extremes):
    """Rows first..last-1 of out's blocks x, v and a: the state's series Y = [x, v] and the acceleration's A summed at
    the rows' times (before t too: rows past the middle of a step are summed from the next step's series), each to the
    order its rows need, the terms it drops under thresholds (x, v, a). One Horner sum is a chain of dependent
    multiply-adds, so sums run side by side: a row's components where there are many, else ROWS rows of each
    component. taus and sums are scratch of ROWS, powers of the series' length. extremes: x's least and largest value
    so far and v's, widened to take in the rows (so that the caller need not pass over out to find them)."""
    n = out.shape[2]
    if 3 * n >= ROWS:
        emit_rows(Y, A, sizes, thresholds, powers, t, grid, first, last, out, lowest, highest, zeroed, extremes)
        return
    p = Y.shape[0] - 1
    for start in range(first, last, ROWS):
        count = min(ROWS, last - start)
        for r in range(count):
            taus[r] = grid[start + r] - t
        top_x, top_v, top_a = 0, 0, 0
        for r in range(count):
            fill_powers(taus[r], powers)
            top_x = max(top_x, row_order(sizes, 0, powers, thresholds[0], p))
            top_v = max(top_v, row_order(sizes, 1, powers, thresholds[1], p))
            top_a = max(top_a, row_order(sizes, 2, powers, thresholds[2], p - 1))
        for i in range(3 * n):
            S, column = (Y, i) if i < 2 * n else (A, i - 2 * n)
            top = top_x if i < n else (top_v if i < 2 * n else top_a)
            for r in range(count):
                sums[r] = S[top, column]
            k = top - 1
            while k >= 1:  # two orders a pass, as in summed (the book's stiff scene's kernel 12 % faster)
                c, below = S[k, column], S[k - 1, column]
                for r in range(count):
                    sums[r] = (sums[r] * taus[r] + c) * taus[r] + below
                k -= 2
            if k == 0:
                c = S[0, column]
                for r in range(count):
                    sums[r] = sums[r] * taus[r] + c
            target = out[i // n, start:start + count, i % n]
            for r in range(count):
                target[r] = sums[r]
            if i < 2 * n:
                widen(target, extremes, i // n)


@no_alloc
def acceleration_series(Y, A, first, last):
    """The acceleration's series A, the velocity's derivative, from the state's Y = [x, v], at DOFs first..last-1."""
    n = Y.shape[1] // 2
    for k in range(A.shape[0]):
        speed, acceleration = Y[k + 1, n + first:n + last], A[k, first:last]
        for i in range(last - first):
            acceleration[i] = (k + 1) * speed[i]
