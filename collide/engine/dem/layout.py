"""The DEM kernel's array layouts: columns of its tables, flags, figures and status codes.

Plain numbers (numpy, never numba), so that the Python side (`collide.dem`) reads them without
loading the compiled engine. Every int is an np.int64, as the kernels index with them.
"""

from __future__ import annotations

import numpy as np

# Bodies: B (N, NB).
B_IM, B_II, B_R, B_M, B_I, B_MAT = range(6)
NB = 6
# Contact tables (as collide.model, with the restitution column turned into the damping ratio
# zeta and sqrt(k_t / k_n) added by `collide.dem.kernel_tables`): k, mu, eps, E*, zeta, rolling
# friction, k_t / k_n, sqrt(k_t / k_n) (the tangential dashpot's factor: taken once a table, not
# once a contact a step).
T_K, T_MU, T_EPS, T_ESTAR, T_ZETA, T_ROLL, T_KTR, T_KTR_ROOT = range(8)
# History per contact: tangential spring (3), its stiffness (for the energy it stores: read
# only when recorded), open interval row, engaged; when recorded, the phase's largest normal
# force so far, as a record row (R_T .. R_MODE of collide.engine.layout, i and j left out: time,
# overlap, normal force, friction force (3), mode), written when the phase ends.
H_XI, H_KT, H_IV, H_ON, H_PEAK = 0, 3, 4, 5, 6
NH = 13
# The contact forces' parts, per body (N, NPT): damping force, friction force, rolling torque.
# (Friction's torque is the rest of the torque: no other part has one.)
PT_DAMP, PT_FRIC, PT_ROLL = 0, 3, 6
NPT = 9
# Flags and figures.
F_DIM, F_SPIN, F_HERTZ, F_TSPRING, F_RECORD, F_MAXSTEPS = range(6)
NFLAG = 6
P_DT, P_TEND, P_REST, P_COAST_GAP, P_FRAME, P_SKIN, P_NOW, P_NOW_STEPS = range(8)
# P_COAST_GAP: a coast (free flight where nothing touches) records frames at its ends only when it
# ends this long after the last frame (0: always; many bodies: the frames' spacing).
# P_NOW, P_NOW_STEPS are written by the run: time reached and steps, read by a progress display.
# P_BOX..: the periodic box as collide.engine.broad's `box` (the periods, 0 where an axis does
# not wrap, then 1.0 if any does).
P_BOX = 8
# Written by the run with P_NOW: the kinetic energy at that step and its peak so far, read by a
# progress display (a run to rest ends when their ratio falls below P_REST).
P_NOW_KINETIC, P_NOW_PEAK = 12, 13
NPAR = 14
# Outputs: stats (int) and figures (float).
S_STEPS, S_STATUS, S_CONTACTS, S_BUILDS, S_PAIRS, S_JUMPS = range(6)
NSTAT = 6
G_FIRST, G_LAST, G_TOUCH, G_OVERLAP, G_FORCE, G_DAMP, G_FRIC, G_ROLL, G_STORED, G_STATUS_T = range(10)
NFIG = 10
OK, NONFINITE, MAXSTEPS = 0, 1, 4
# Record layouts shared with the event engine (collide.engine.layout): knots, records, intervals.
NK, NR = 23, 9
EP_T, EP_DAMP, EP_FRIC, EP_ROLL, EP_STORED = range(5)
NEP = 5
for _name, _value in list(globals().items()):
    if _name.isupper() and type(_value) is int:
        globals()[_name] = np.int64(_value)
