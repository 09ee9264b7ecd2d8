"""The event engine's entry: `simulate` runs one scene from its bodies' state to its end, as
windows of islands, and returns what it recorded.
"""

from __future__ import annotations

import math

import numpy as np

from collide.engine.event.windows import windows
from collide.engine.flight import bring
from collide.engine.jit import jit
from collide.engine.layout import (
    CN_IVALS,
    CN_KNOTS,
    CN_OPEN,
    CN_RECS,
    F_DT_MIN,
    FL_RECORD,
    G_Q,
    G_S,
    G_V,
    G_W,
    G_WK,
    GI_KNOT,
    K_T,
    NF,
    NK,
    NR,
    NS,
    V_END,
)
from collide.engine.records import add_knot


@jit
def simulate(G, tables, WP, grav, weights, fl, fp):
    """Run one scene from the state in G (base time 0) to its end. Returns (final time, knots,
    contact records, contact intervals, counters, figures); G holds the final state."""
    n = G.shape[0]
    GI = np.full((n, 2), -1, np.int64)
    KN = np.empty((max(64, 4 * n), NK))
    RC = np.empty((64, NR))
    IV = np.empty((16, 4))
    OP = np.empty(16, np.int64)
    CNT = np.zeros(4, np.int64)
    ST = np.zeros(NS, np.int64)
    FG = np.zeros(NF)
    FG[F_DT_MIN] = math.inf
    acc = np.zeros(3)
    for d in range(3):
        acc[d] = grav[d]
    if fl[FL_RECORD]:
        for i in range(n):
            KN = add_knot(KN, CNT, 0.0, i, 1.0, G, i, G_S, G_V, G_W, G_Q, acc, 0.0)
            GI[i, GI_KNOT] = i
    KN, RC, IV, OP, t = windows(G, GI, tables, WP, grav, weights, fl, fp, (KN, RC, IV, OP), CNT, ST, FG)
    for i in range(n):
        bring(G, i, t, grav, fl)
        if fl[FL_RECORD] and not (GI[i, GI_KNOT] >= 0 and KN[GI[i, GI_KNOT], K_T] == t):
            KN = add_knot(KN, CNT, t, i, 1.0, G, i, G_S, G_V, G_W, G_Q, acc, G[i, G_WK])
            GI[i, GI_KNOT] = CNT[CN_KNOTS] - 1
    for k in range(CNT[CN_OPEN]):
        IV[OP[k], V_END] = t
    return t, KN[:CNT[CN_KNOTS]].copy(), RC[:CNT[CN_RECS]].copy(), IV[:CNT[CN_IVALS]].copy(), ST, FG
