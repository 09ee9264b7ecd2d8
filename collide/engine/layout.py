"""The event engine's tables and settings: column indices, status codes, tolerances and tuning
constants, shared by the compiled kernels and by the Python that packs and reads their tables
(collide/stepper.py, the recording, the viewer).

This module imports neither numba nor `collide.engine.jit`/`collide.engine.tier`: reading a
column index must never decide whether this process runs the compiled kernels, nor start a
compile (the viewer reads knots and records and runs no kernel). The kernels freeze these values
into their machine code; `collide.engine.tier` hashes this file into the compiled cache's key.

Tables (float64 unless noted; columns named by the constants below):

====  ===========  ========================================================================
name  shape        rows, columns
====  ===========  ========================================================================
G     (N, NG)      bodies: state s, v, w, q at base time tb; dissipated work share; 1/m,
                   1/I, radius, m, I, material
GI    (N, 2) int   bodies: local row in the running island (-1), last knot row
X     (A, NX)      an island's bodies: state, start state, accelerations, scratch; constants
XI    (A,) int     an island's bodies: global row
C     (K, NC)      an island's engaged contacts: normal, overlap, arms, normal force,
                   parameters, held slip direction, friction force, tangent basis
CI    (K, NCI) int contacts: local i, local j (or -1 - wall), global i, global j, mode, ...
Q     (K, 3) int   an island's candidate contacts: global i, j (or -1 - wall), engaged
QF    (K, NQF)     candidates: touching distance, overlaps and rates at trial ends
E     (2K, NE)     friction mode events: values and rates at a step's start, a trial's end
                   and the longest trial at whose end none had crossed
WP    (W, 6)       walls: a point and the outward unit normal
====  ===========  ========================================================================

Records (the run's output): knots KN (K_*), contact records RC (R_*), contact intervals IV
(V_*), their counts CNT (CN_*); counters ST (S_*) and figures FG (F_*); settings fl (FL_*, int)
and fp (FP_*, float); contact parameter tables (TP_*).
"""
from __future__ import annotations

import numpy as np

from collide.integrators import SUZUKI4, YOSHIDA4, YOSHIDA6

BAND, SLIDE, STICK = 0, 1, 2
# A contact with a tangential spring (C_KTR > 0) sticks in SPRING (the spring and its dashpot on the
# stretch C_XI: a smooth force, no rigid hold) and slips in SLIDE (the cap, the stretch the one that
# holds it: `collide.engine.dem.tangential`); it has no band.
SPRING = 3
EDGE_TOL = 1e-9  # relative to the speed scale: how close to the band's edge counts as on it
MODE_TOL = 0.5 * EDGE_TOL
STICK_SCALE = 1e-3  # s: turns a friction force into a slip change, to compare with EDGE_TOL
# A stuck slip whose hold force comes to zero crosses the band to its other edge in a time
# `crossing` (README "Friction as events"); taken as an impulse there when the bodies' shift
# that makes, times omega (FLIP_SAFETY over), stays within FLIP_SHARE of the event tolerance
# (`flips`): what a landed mode change may leave (MODE_TOL), for one decision that replaces two
# landings. CI_EDGE FLIP marks it for `decide`.
FLIP, FLIP_SAFETY = 3, 4.0
FLIP_SHARE = MODE_TOL / EDGE_TOL
# A stuck contact's mode change (its margin to mu F_n, its hold force through zero) landed late
# errs by what the friction held past it does: within MODE_TOL, this many times over (step_events).
LATE_SAFETY = 4.0
TOUCH_TOL = 1e-12  # relative overlap below which spheres count as just touching
FIXED_POINT = 12  # most iterations of an implicit kick
# A pass of a kick's fixed point shrinks its change by a factor of h |dG/dv| (the hold rates'
# velocity terms: |v_rel| / dist and the spins) times at most this. Measured on the break:
# 0.14 of it in the median kick, 0.77 in the 99th percentile, 0.92 at most (changes above
# round-off only).
CONTRACTION_SAFETY = 4.0
WINDOW_STEPS = 64  # a window spans this many steps of the stiffest engaged contact
# ... and, doubling from window to window, up to this many while its bodies are each alone on a
# wall (`lone_on_walls`) and nothing is recorded: a rolling ball's cycles repeat across it
# (rest_phase), and a stepped one still reports progress every such window.
LONE_WINDOW_STEPS = 65536
ISLAND_SLACK = 4  # ... unless its islands grow past this many times the largest touching cluster
# A window's candidates: bodies reach at most this many times their speed bound's distance. A
# window redone doubles it for that window only: kept for the rest of the run, one redone window
# in gas-box's 410 doubled every later window's reach, its islands spanned the box and the run
# took 3x as long.
WINDOW_SAFETY = 1.5
STALL_LIMIT = 64
# Out of the plane, a slip smaller than a step's friction impulse turns on a time scale far below
# the step (a stiff layer), which compositions with negative substeps follow at about third
# order (measured 3.2). Steps there are dt (omega dt)^0.9, so that the layer's error goes as
# (omega dt)^(1.9 x 3.2), about the sixth order of the rest. Two impulses: a slip closing in on
# the band is caught a step before it gets there.
STIFF_SLIDE_IMPULSES = 2.0
STIFF_SLIDE_POWER = 0.9
# ... unless a step spans one to this many of the layer's time scales (|slip| / (mu F_n K)): the
# compositions' negative substeps follow it worst there. A slip that slides on while its friction
# barely yields stays in the layer for many steps (a 3D break: 0.14 microseconds against steps of
# 0.5-12); at 4 time scales a step took 30 % off such a slip, and the outcome erred 500 times
# the tolerance (four balls, tol 1e-6) and stopped converging with it. Such steps are cut to one
# time scale. Beyond this many the implicit kick's root follows the layer's slow motion (the
# slip along the force that drives it). Measured: 30 left four balls 17 times the tolerance
# off, 100 and 300 within 1.2 (300: 30 % more steps).
STIFF_SLIDE_SPAN = 100.0
DIP_SAMPLES = 16  # points of a trial step where a mode value's cubic is checked for a dip below zero
TINY_LIMIT = 20000  # steps in a row under a thousandth of the contact's step
GRAZE_SHARE = 1e-6  # a step this share of its full length, landed on a forced band value: see run_island
LATE = 2  # Q_ENG of a contact engaged from a step's start after the step found it pressing
MAX_RETRIES = 24  # a window redone this often, each 4x shorter, has met a contact it cannot foresee
NO_CONTACT_TAIL = 1.0  # s: how long a run with no contact at all lasts
EPS64 = 2.220446049250313e-16
VERLET = np.ones(1)  # the weights of one kick-drift-kick substep
YOSHIDA = np.array(YOSHIDA4)  # three substeps: the event search's longer nudges
SUZUKI = np.array(SUZUKI4)  # five substeps, fourth order
SIXTH7 = np.array(YOSHIDA6)  # seven substeps, sixth order
# Local errors of one step of omega h on an oscillator (measured): Verlet (omega h)^3 / 12,
# Yoshida 0.0281 (omega h)^5, Suzuki 0.00266 (omega h)^5, Yoshida's sixth order 0.0018 (omega h)^7.
# A nudge of the event search may leave a thousandth of the tolerance.
VERLET_ERROR, YOSHIDA_ERROR, SUZUKI_ERROR, SIXTH7_ERROR = 1.0 / 12.0, 0.0281, 0.00266, 0.0018
KAHAN6_ERROR = 1.73e-4  # one step's error on an oscillator over (omega h)^7 (1.73e-4 at 0.05, 1.82e-4 at 0.2)
# A trial from a step's start short enough that a Yoshida step's error there is at most this share
# of a whole kahan6 step's is a Yoshida step (four breaks at tol 1e-6, their errors against tol
# 1e-10: within 3 % of all-kahan6 trials at 0.1; at 1, one of them 16 % higher); a little longer,
# on the same share, one of Suzuki's or of Yoshida's sixth order (18 planar scenes at tol 1e-6
# and 1e-7: their errors within 5 % of what they were with kahan6 there).
SHORT_SHARE = 0.1
NUDGE_SHARE = 1e-3
FORESEE_SPAN = 1e-4  # of the step: the differences that foresee events
EVENT_RES = 1e-9  # of the step: an event (a contact's start or end, a mode's change) bracketed this closely has landed
CREEP_LIMIT = 3  # short trials in a row whose aim shrank by less than half: the step ends short
# Trials of one step's event search: a jump in a mode value, bisected from the whole step to
# EVENT_RES, takes 30, after those of the step's other events.
TRIALS = 64
AIM = 1.02  # a first trial aimed at an event its start rates foresee ends this far past it

# G: bodies.
G_S, G_V, G_W, G_Q, G_TB, G_WK, G_IM, G_II, G_R, G_M, G_I, G_MAT = 0, 3, 6, 9, 13, 14, 15, 16, 17, 18, 19, 20
NG = 21
GI_LOC, GI_KNOT = 0, 1
# X: an island's bodies.
X_S, X_V, X_W, X_Q = 0, 3, 6, 9
X_S0, X_V0, X_W0, X_Q0 = 13, 16, 19, 22
X_A, X_F, X_L, X_V1, X_W1, X_T, X_UA, X_UL, X_FO, X_VB, X_WB = 26, 29, 32, 35, 38, 41, 44, 47, 50, 53, 56
X_IM, X_II, X_R, X_M, X_I = 59, 60, 61, 62, 63
X_SF, X_SL = 64, 67  # sliding contacts' part of X_F, X_L
X_FP, X_LP, X_HP = 70, 73, 76  # the kick before's X_F, X_L and closing span (row 0; 0: none)
X_F0, X_L0 = 77, 80  # the friction accelerations at the step's start (with X_S0...)
# Row 0: the step's map of time (`substep.mapped_step`): its kind (MAP_NONE, MAP_START, MAP_END,
# MAP_BOTH),
# the step's start's time past a Hertz start (MAP_START), that start region's length, the
# phase's step, the power of the map, and the time offset the last step call reached.
X_MK, X_MU, X_MH, X_MD, X_MP, X_MO = 83, 84, 85, 86, 87, 88
X_MR = 89  # 1 / omega, the stiffest contact's time scale
NX = 90
MAP_NONE, MAP_START, MAP_END, MAP_BOTH = 0, 1, 2, 3
# A Hertz contact's start and end regions: this share of the time its approach takes to reach its
# largest overlap at its rate (at least of 1 / omega, the stiffest contact's), stepped over s with
# t - t_start (or t_end - t) = H s^P, uniform in s, the last step of the start region about the
# phase's step: there every force is smooth in s (delta^1.5 = s^(1.5 P), Hertz's dashpot
# delta^(1/4) = s^(P/4): P = 4 damped, 2 undamped).
MAP_SHARE = 0.6
# C / CI: an island's engaged contacts.
C_N, C_DELTA, C_DIST, C_LIF, C_LJF, C_LIS, C_LJS, C_FN = 0, 3, 4, 5, 6, 7, 8, 9
C_K, C_MU, C_EPS, C_REACH, C_HELD, C_FF, C_B = 10, 11, 12, 13, 14, 17, 20
C_INV = 26  # 1 / C_DIST of a pair (the slip rates' turning terms divide by it)
C_GV = 27  # in the plane, a stuck contact's hold rate's velocity terms along e1, at a kick's last pass
C_SH = 28  # what takes j's centre to its image nearest i's in a periodic box (QF_SH's; else 0)
C_GAMMA = 31  # the restitution's dashpot coefficient (kg/s; 0: undamped): the DEM kernel's `dashpot`
# (Hertz: at the overlap C_K is taken at, a bound for the kicks' contraction; the kicks take it at
# the contact's overlap, from C_ZETA and C_MSTAR)
# Hertz (C_ESTAR > 0; 0: the linear spring C_K): E*, R*, and the dashpot's damping ratio and m*.
C_ESTAR, C_RSTAR, C_ZETA, C_MSTAR = 32, 33, 34, 35
# A tangential spring (C_KTR > 0: k_t / k_n): the stretch along the tangent z x n (in the plane),
# a state stepped with the bodies (the drifts integrate the slip into it), and its value at the
# step's start (every trial starts from it).
C_XI, C_XI0, C_KTR = 36, 37, 38
NC = 39
CI_I, CI_J, CI_GI, CI_GJ, CI_MODE, CI_Q, CI_EDGE, CI_RETRIED, CI_FLIPPED, CI_GRAZE = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9
# CI_RETRIED, CI_FLIPPED: `decide`'s marks (arrays of its own were allocated at every call);
# CI_GRAZE: run_island's, for the next step.
# CI_PRESS: the side (+1, -1) of a damped sliding contact's F_n at its step's start, whose branch
# of the cap mu max(F_n, 0) the step keeps (0 while `decide` chooses the modes: the cap itself);
# its second mode value is F_n on that side, so F_n through zero either way is a located event.
CI_PRESS = 10
NCI = 11
# Q / QF: an island's candidate contacts.
Q_I, Q_J, Q_ENG = 0, 1, 2
QF_REACH, QF_D0, QF_R0, QF_D1, QF_R1, QF_DP, QF_RP, QF_DB, QF_RB = 0, 1, 2, 3, 4, 5, 6, 7, 8
# QF_SH: the image shift of a pair in a periodic box (3), fixed for its window: the nearest
# image at the window's start, which no body moves far enough within it to change (FP_CAP).
QF_SH = 9
NQF = 12
E_V0, E_R0, E_V1, E_R1, E_VC, E_RC, E_FORCED = 0, 1, 2, 3, 4, 5, 6
NE = 7
# Settings: flags (int) and figures (float).
FL_SPIN, FL_FRICTION, FL_SEED, FL_PLANAR, FL_RECORD, FL_AUTO, FL_MAXSTEPS, FL_DIM, FL_TURNS = range(9)
# FL_DAMPED: some contact has a dashpot (a restitution below 1): a velocity-dependent normal force,
# in the kicks with the friction (FL_FRICTION is set with it).
FL_DAMPED = 9
FL_HERTZ = 10  # the contacts are Hertz's
FL_SPRING = 11  # friction has a tangential spring (2D): its stretches are kept per pair across phases
NFL = 12
FP_DT, FP_OMEGA_H, FP_TEND, FP_TAIL, FP_SCALE, FP_SLOW, FP_EVENT_TOL, FP_END_SLOW, FP_NOW, FP_NOW_STEPS = range(10)
# FP_NOW, FP_NOW_STEPS are written by the run: time reached and steps, read by a progress display.
# FP_BOX..: the periodic box (collide.engine.broad's `box`: the periods, 0 where an axis does not
# wrap, then 1.0 if any does); FP_CAP: how far a body may move between two looks at its nearest
# images (a jump or a window longer is cut).
FP_BOX, FP_CAP = 10, 14
NFP = 15
# Contact parameter tables: pairs (M, M, NP), walls (M, NP).
TP_K, TP_MU, TP_EPS = range(3)
TP_ESTAR = 3  # Hertz's E* (the model's TABLE_ESTAR)
TP_ZETA = 4  # the event engine's tables carry the damping ratio where the model's hold the restitution
TP_KTR = 6  # the tangential spring's k_t / k_n (the model's TABLE_KTR)
# Records.
# Knots: a body's exact state at a time, with its acceleration just before (K_A) and just after
# (K_AN): a friction mode change or the seed's per-step forces make it jump there.
K_T, K_BODY, K_FREE, K_S, K_V, K_W, K_Q, K_A, K_AN, K_WORK = 0, 1, 2, 3, 6, 9, 12, 16, 19, 22
NK = 23
R_T, R_I, R_J, R_DELTA, R_FN, R_FX, R_FY, R_FZ, R_MODE = range(9)
NR = 9
V_I, V_J, V_START, V_END = range(4)
CN_KNOTS, CN_RECS, CN_IVALS, CN_OPEN = range(4)
S_STEPS, S_WINDOWS, S_STATUS, S_CONTACTS, S_RETRIES, S_UNLOCATED, S_REST, S_ATTEMPTS, S_JUMPS = range(9)
NS = 9  # S_REST: of the steps, intervals of a sphere on a wall in closed form (exactly); S_ATTEMPTS:
# whole steps tried from a step's start (the event search's nudges not counted); S_JUMPS:
# stretches where nothing touched, crossed in closed form (to a contact, or to the run's end)
F_MAX_OVERLAP, F_DT_MIN, F_STATUS_T, F_STATUS_A, F_STATUS_B, F_MAX_FORCE, F_UNLOCATED_T = range(7)
NF = 7
OK, NONFINITE, ENERGY, STALL, MAXSTEPS, SINGULAR = range(6)
# A damped tangential spring at a falling cap, its point moving along the force: the law resets its
# stretch to the cap again and again (a sawtooth whose teeth shrink to nothing as a slip ends),
# which the islands do not follow yet (`spring.spring_mode` marks it in CI_EDGE: TOOTH).
SAWTOOTH = 6
TOOTH = 5
YES, NO = 1, 0
# Numba compiles one specialisation per literal int an argument is called with: as numpy ints
# these constants are plain int64 to it, and every function compiles once.
for _name, _value in list(globals().items()):
    if _name.isupper() and type(_value) is int:
        globals()[_name] = np.int64(_value)
