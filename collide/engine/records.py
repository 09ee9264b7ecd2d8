"""What a run records: knots (a body's exact state at a time), contact records at each step's
end and contact intervals (start, end); each step's dissipated work shared among its bodies; the
tail a run keeps going after its last separation.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.jit import jit, jit_call
from collide.engine.layout import (
    C_DELTA,
    C_FF,
    C_FN,
    CI_GI,
    CI_GJ,
    CI_MODE,
    CN_IVALS,
    CN_KNOTS,
    CN_OPEN,
    CN_RECS,
    FL_FRICTION,
    G_WK,
    GI_KNOT,
    K_A,
    K_AN,
    K_BODY,
    K_FREE,
    K_Q,
    K_S,
    K_T,
    K_V,
    K_W,
    K_WORK,
    NO_CONTACT_TAIL,
    Q_ENG,
    Q_I,
    Q_J,
    R_DELTA,
    R_FN,
    R_FX,
    R_I,
    R_J,
    R_MODE,
    R_T,
    S_CONTACTS,
    SPRING,
    STICK,
    V_END,
    V_I,
    V_J,
    V_START,
    X_A,
    X_F,
    X_Q,
    X_S,
    X_V,
    X_W,
)
from collide.engine.numerics import grow


@jit
def add_knot(KN, CNT, t, g, free, X, a, sc, vc, wc, qc, acc, work):
    """Append body g's state at t from row a of X (or of G, with the columns given)."""
    KN = grow(KN, CNT[CN_KNOTS])
    put_knot(KN, CNT, t, g, free, X, a, sc, vc, wc, qc, acc, work)
    return KN


@jit_call
def put_knot(KN, CNT, t, g, free, X, a, sc, vc, wc, qc, acc, work):
    """`add_knot` into a KN with room for it (a caller that grew it once for many knots; called
    without reference counting)."""
    r = CNT[CN_KNOTS]
    KN[r, K_T] = t
    KN[r, K_BODY] = g
    KN[r, K_FREE] = free
    for d in range(3):
        KN[r, K_S + d] = X[a, sc + d]
        KN[r, K_V + d] = X[a, vc + d]
        KN[r, K_W + d] = X[a, wc + d]
        KN[r, K_A + d] = acc[d]
        KN[r, K_AN + d] = acc[d]
    for d in range(4):
        KN[r, K_Q + d] = X[a, qc + d]
    KN[r, K_WORK] = work
    CNT[CN_KNOTS] += 1


@jit
def intervals(Q, nq, t, IV, OP, CNT, ST):
    """Open an interval for every newly engaged candidate, close the island's that ended.
    OP holds the rows of open intervals (CNT[CN_OPEN] of them). Returns the grown buffers."""
    IV = grow(IV, CNT[CN_IVALS] + nq)
    if CNT[CN_OPEN] + nq >= OP.shape[0]:
        more = np.empty(2 * OP.shape[0] + nq + 16, np.int64)
        more[:OP.shape[0]] = OP
        OP = more
    k = 0
    while k < CNT[CN_OPEN]:
        row = OP[k]
        gi, gj = int(IV[row, V_I]), int(IV[row, V_J])
        close = False
        for q in range(nq):
            if Q[q, Q_I] == gi and Q[q, Q_J] == gj:
                close = Q[q, Q_ENG] == 0
                break
        if close:
            IV[row, V_END] = t
            CNT[CN_OPEN] -= 1
            OP[k] = OP[CNT[CN_OPEN]]
        else:
            k += 1
    for q in range(nq):
        if Q[q, Q_ENG] == 0:
            continue
        found = False
        for k in range(CNT[CN_OPEN]):
            row = OP[k]
            if int(IV[row, V_I]) == Q[q, Q_I] and int(IV[row, V_J]) == Q[q, Q_J]:
                found = True
                break
        if found:
            continue
        row = CNT[CN_IVALS]
        IV[row, V_I] = Q[q, Q_I]
        IV[row, V_J] = Q[q, Q_J]
        IV[row, V_START] = t
        IV[row, V_END] = math.nan
        OP[CNT[CN_OPEN]] = row
        CNT[CN_OPEN] += 1
        CNT[CN_IVALS] += 1
        ST[S_CONTACTS] += 1
    return IV, OP


@jit
def record_step(KN, RC, CNT, G, GI, X, XI, C, CI, na, nc, t, fl):
    """Knots of the stepped bodies and records of the engaged contacts at the end of a step."""
    acc = np.empty(3)
    for a in range(na):
        g = XI[a]
        for d in range(3):
            acc[d] = X[a, X_A + d] + (X[a, X_F + d] if fl[FL_FRICTION] else 0.0)
        KN = add_knot(KN, CNT, t, g, 0.0, X, a, X_S, X_V, X_W, X_Q, acc, G[g, G_WK])
        GI[g, GI_KNOT] = CNT[CN_KNOTS] - 1
    for c in range(nc):
        RC = grow(RC, CNT[CN_RECS])
        r = CNT[CN_RECS]
        RC[r, R_T] = t
        RC[r, R_I] = CI[c, CI_GI]
        RC[r, R_J] = CI[c, CI_GJ]
        RC[r, R_DELTA] = C[c, C_DELTA]
        RC[r, R_FN] = C[c, C_FN]
        for d in range(3):
            RC[r, R_FX + d] = C[c, C_FF + d] if fl[FL_FRICTION] else 0.0
        # A spring's stick is recorded as stick (2), as the DEM kernel's is.
        mode = CI[c, CI_MODE]
        RC[r, R_MODE] = (STICK if mode == SPRING else mode) if fl[FL_FRICTION] else 0.0
        CNT[CN_RECS] += 1
    return KN, RC


@jit
def share(G, XI, na, work):
    """An island step's dissipated work, shared among its stepped bodies (their sum is exact at
    the step's end, where every one of them has a knot)."""
    if work != 0.0 and na > 0:
        for a in range(na):
            G[XI[a], G_WK] += work / na


@jit
def tail_after(tail, IV, CNT):
    """After the last separation, keep going long enough to see the bodies part."""
    if tail == tail:
        return tail
    first, last = math.inf, -math.inf
    for k in range(CNT[CN_IVALS]):
        first = min(first, IV[k, V_START])
        if IV[k, V_END] == IV[k, V_END]:
            last = max(last, IV[k, V_END])
    if last == -math.inf:
        return NO_CONTACT_TAIL
    return max(2.0 * (last - first), 0.1 * last)
