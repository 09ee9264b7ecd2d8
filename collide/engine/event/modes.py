"""Friction modes and their events (README "Friction as events"): each contact's mode values
and rates (`mode_events`: a slide's slip above the band's edge and a damped one's F_n through
zero, a stuck contact's margin to mu F_n and its hold force), the modes chosen where they change
(`decide`), and a stuck slip whose hold comes to zero taken across the band as one impulse
(`flips`).
"""

from __future__ import annotations

import math

from collide.engine.event.contact import cap, dashpots, press, response, slip, slip_rate
from collide.engine.event.forces import friction
from collide.engine.event.spring import slide_sign, slide_value, spring_mode
from collide.engine.event.substep import settle
from collide.engine.jit import jit_call, jit_inline
from collide.engine.layout import (
    BAND,
    C_EPS,
    C_FF,
    C_GAMMA,
    C_HELD,
    C_KTR,
    C_MU,
    C_N,
    CI_EDGE,
    CI_FLIPPED,
    CI_MODE,
    CI_PRESS,
    CI_RETRIED,
    E_V0,
    E_V1,
    EDGE_TOL,
    FL_DAMPED,
    FL_PLANAR,
    FL_SEED,
    FL_SPIN,
    FL_SPRING,
    FLIP,
    FLIP_SAFETY,
    FLIP_SHARE,
    MODE_TOL,
    NO,
    SLIDE,
    SPRING,
    STICK,
    STICK_SCALE,
    X_A,
    X_F,
    X_L,
    X_T,
    X_UA,
    X_V,
    X_W,
    YES,
)


@jit_call
def mode_events(X, C, CI, E, na, nc, vcol, rcol, stuck, A, b, fl, scale, fresh, known):
    """Friction mode event values (2C) into E[:, vcol] and their rates into E[:, rcol], in speed
    units over `scale`, at the state in X (geometry in C, X_A set). Slide: |slip| - eps; band:
    eps - |slip|; stick: the margin to mu F_n and the hold force's component against the held
    slip, as the slip change they would make over STICK_SCALE (rates NaN: no closed form).
    The stuck contacts' hold system is built with `fresh`, else it is the one in A: a state that
    ends a step or a decision, whose `settle` built it at this geometry and these modes. Leaves
    the friction forces in C_FF. With `known`, those forces (C_FF, X_F, X_L) are already this
    state's: a step's end, whose closing kick solved them at its velocities (the settling of
    stuck slips after it moves them by the kick's fixed-point tolerance: a mode value by 1e-12,
    far below MODE_TOL), and the solve is skipped. Returns False if the hold system is singular."""
    spin, seed, planar = fl[FL_SPIN], fl[FL_SEED], fl[FL_PLANAR] == YES
    if not known and not friction(X, C, CI, na, nc, X_V, X_W, stuck, A, b, fl, 0.0, fresh):
        return False
    for a in range(na):
        for d in range(3):
            X[a, X_T + d] = X[a, X_A + d] + X[a, X_F + d]
    for c in range(nc):
        second = nc + c
        if C[c, C_KTR] > 0.0 and CI[c, CI_MODE] == SPRING:
            # The spring's force within the cap, as the slip change it makes over STICK_SCALE.
            k = response(X, C, CI, c, spin) * STICK_SCALE / scale
            fx, fy = C[c, C_FF], C[c, C_FF + 1]
            E[c, vcol] = (cap(C, CI, c) - math.sqrt(fx * fx + fy * fy)) * k
            E[c, rcol] = math.nan
            E[second, vcol] = 1.0
            E[second, rcol] = 0.0
            continue
        if CI[c, CI_MODE] == STICK:
            k = response(X, C, CI, c, spin) * STICK_SCALE / scale
            fx, fy, fz = C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2]
            fmag = math.sqrt(fx * fx + fy * fy + fz * fz)
            E[c, vcol] = (cap(C, CI, c) - fmag) * k
            E[second, vcol] = -(fx * C[c, C_HELD] + fy * C[c, C_HELD + 1] + fz * C[c, C_HELD + 2]) * k
            E[c, rcol] = math.nan
            E[second, rcol] = math.nan
            continue
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar)
        gx, gy, gz = slip_rate(X, C, CI, c, X_V, X_W, X_T, X_L, spin, seed, YES, planar)
        if CI[c, CI_MODE] == SLIDE and C[c, C_KTR] > 0.0:
            # A spring's slide (`spring.slide_value`): with a dashpot -s v_e, its rate -s v_e';
            # without, less c' (its rate left to differences, as a stuck contact's).
            s = slide_sign(C, c)
            ex, ey = -C[c, C_N + 1], C[c, C_N]
            E[c, vcol] = slide_value(X, C, CI, c, s, sx * ex + sy * ey) / scale
            E[c, rcol] = -s * (gx * ex + gy * ey) / scale if C[c, C_GAMMA] > 0.0 else math.nan
        if CI[c, CI_MODE] == SLIDE:
            # |slip| - eps, with |slip| counted negative once the slip points against the way it
            # slid at the step's start: a slip reversing through the band within a step then
            # still changes sign, and one that turns as it slows lands where |slip| = eps.
            hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
            mag = math.sqrt(sx * sx + sy * sy + sz * sz)
            along = sx * hx + sy * hy + sz * hz
            outward = (sx * gx + sy * gy + sz * gz) / mag if mag > 0 else 0.0
            if C[c, C_KTR] > 0.0:
                pass
            elif planar:
                sign = 1.0 if along >= 0 else -1.0
                E[c, vcol] = (sign * mag - C[c, C_EPS]) / scale
                E[c, rcol] = sign * outward / scale
            else:
                # Out of the plane a slip near the band can turn past a right angle off the way
                # it slid without slowing to the band (its direction slaved to the other forces):
                # the signed |slip| jumped there, and the root search bisected the jump to the
                # clock (40 trials, in a pile of 27 spheres). (|slip| + slip . held) / 2, that is
                # |slip| cos^2 of half the turn, is continuous, |slip| while the slip keeps its
                # way and 0 reversed: a reversal still changes sign, and a slip that turns as it
                # slows lands a little before |slip| = eps, where it slides on, redirected.
                E[c, vcol] = (0.5 * (mag + along) - C[c, C_EPS]) / scale
                E[c, rcol] = 0.5 * (outward + gx * hx + gy * hy + gz * hz) / scale
            if C[c, C_GAMMA] > 0.0 and C[c, C_MU] > 0.0:
                # A damped F_n passes zero as the contact eases out (it pulls at its end) and
                # may turn back: there the cap mu max(F_n, 0) has its kink, an event as a mode
                # change is (the slide goes on, with or without a force). F_n on its side at the
                # step's start (CI_PRESS), as the slip change mu F_n makes over STICK_SCALE
                # (Hertz's through `press`'s weighting, smooth to the contact's end).
                side = -1.0 if CI[c, CI_PRESS] < 0 else 1.0
                k = side * C[c, C_MU] * response(X, C, CI, c, spin) * STICK_SCALE / scale
                value, rate = press(X, C, CI, c, X_T)
                E[second, vcol] = value * k
                E[second, rcol] = rate * k
            else:
                E[second, vcol] = 1.0
                E[second, rcol] = 0.0
        elif planar:
            # In the plane the band is a segment along the tangent e = z x n, its edges where
            # the slip along e is eps and -eps: values smooth in the slip. eps - |slip| has a
            # kink at zero slip: a slip crossing the band made it rise and fall back with the
            # far edge's, and a root search on it crept (11 trials for one event).
            ex, ey = -C[c, C_N + 1], C[c, C_N]
            along, rate = sx * ex + sy * ey, gx * ex + gy * ey
            E[c, vcol] = (C[c, C_EPS] - along) / scale
            E[c, rcol] = -rate / scale
            E[second, vcol] = (C[c, C_EPS] + along) / scale
            E[second, rcol] = rate / scale
        else:
            # Any edge: eps - |slip| (|slip|' = slip . slip' / |slip|, friction included); it
            # starts at zero when the band is entered from its edge, so the far edge is watched
            # too: eps + the slip along its direction at the step's start.
            mag = math.sqrt(sx * sx + sy * sy + sz * sz)
            hx, hy, hz = C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2]
            E[c, vcol] = (C[c, C_EPS] - mag) / scale
            E[c, rcol] = -(sx * gx + sy * gy + sz * gz) / mag / scale if mag > 0 else 0.0
            E[second, vcol] = (C[c, C_EPS] + sx * hx + sy * hy + sz * hz) / scale
            E[second, rcol] = (gx * hx + gy * hy + gz * hz) / scale
    return True


@jit_call
def decide(X, C, CI, na, nc, stuck, A, b, fl, scale):
    """Modes of the engaged contacts at this state (at a phase start and after every step).

    Outside the band: slide; inside: band; on its edge (within the event tolerance, so that a
    step landed on a mode change switches): stick if the force that holds the slip there (solved
    with the other stuck contacts) is within mu F_n and against the slip, else slide (beyond
    mu F_n) or band (not against it). A stuck slip is held along its hold force's reverse; in 3D
    a slip that reaches the edge off that direction is turned onto it (the limit of the fast
    turning along the edge that the law gives there). Returns (work dissipated, ok, whether the
    hold system left in A is not these modes': 3D edge contacts that slide on were settled held,
    whether the friction forces left are this state's: see `mode_events`' `known`)."""
    spin, planar, seed = fl[FL_SPIN], fl[FL_PLANAR], fl[FL_SEED]
    tol = EDGE_TOL * scale
    edges = 0
    flipped_any = False
    if fl[FL_SPRING] and fl[FL_DAMPED]:
        dashpots(X, C, CI, nc, X_V, X_UA)  # the springs' caps take F_n at these velocities (X_UA: scratch)
    for c in range(nc):
        CI[c, CI_RETRIED] = NO
        CI[c, CI_FLIPPED] = NO
        if C[c, C_KTR] > 0.0:
            # A tangential spring: its own mode, alone (no hold couples it to its neighbours).
            CI[c, CI_EDGE] = 0
            spring_mode(X, C, CI, c, spin, tol)
            continue
        sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar == YES)
        mag = math.sqrt(sx * sx + sy * sy + sz * sz)
        if mag > 0:
            C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2] = sx / mag, sy / mag, sz / mag
        flip = CI[c, CI_EDGE] == FLIP
        CI[c, CI_EDGE] = 0
        if abs(mag - C[c, C_EPS]) <= tol:
            CI[c, CI_MODE] = STICK
            CI[c, CI_EDGE] = 1
            edges += 1
            if flip:
                # Its slip goes to the band's other edge (settled there below) and is held
                # there: the hold force goes on through zero, now against the reversed slip.
                for d in range(3):
                    C[c, C_HELD + d] = -C[c, C_HELD + d]
                CI[c, CI_FLIPPED] = YES
                flipped_any = True
        elif mag > C[c, C_EPS]:
            CI[c, CI_MODE] = SLIDE
        else:
            CI[c, CI_MODE] = BAND
    solved = False  # the last friction solve was at the final modes: its hold system is settle's
    for _ in range(2 * nc + 2):
        if not friction(X, C, CI, na, nc, X_V, X_W, stuck, A, b, fl, 0.0, YES):
            return 0.0, False, False, False
        changed = False
        # An edge contact that another's change left sliding with its slip heading into the band,
        # or in the band with its slip heading out, is in no consistent mode: it is held again
        # (once) and judged by its hold force with the others' modes as they now are. Left so,
        # the slide crossed the band unseen within the step (its value starts at zero) and the
        # outcome moved by 1e-3 between tolerances (two balls and a floor changing at once).
        if edges:
            for a in range(na):
                for d in range(3):
                    X[a, X_T + d] = X[a, X_A + d] + X[a, X_F + d]
            limit = tol / STICK_SCALE
            for c in range(nc):
                if CI[c, CI_EDGE] != 1 or CI[c, CI_MODE] == STICK or CI[c, CI_RETRIED]:
                    continue
                sx, sy, sz = slip(X, C, CI, c, X_V, X_W, spin, planar == YES)
                gx, gy, gz = slip_rate(X, C, CI, c, X_V, X_W, X_T, X_L, spin, seed, YES, planar == YES)
                mag = math.sqrt(sx * sx + sy * sy + sz * sz)
                outward = (sx * gx + sy * gy + sz * gz) / mag if mag > 0 else 0.0
                if (CI[c, CI_MODE] == SLIDE and outward < -limit) or (CI[c, CI_MODE] == BAND and outward > limit):
                    CI[c, CI_MODE] = STICK
                    CI[c, CI_RETRIED] = YES
                    changed = True
        if changed:
            continue
        for c in range(nc):
            if CI[c, CI_MODE] != STICK:
                continue
            force_tol = tol / (response(X, C, CI, c, spin) * STICK_SCALE)
            fx, fy, fz = C[c, C_FF], C[c, C_FF + 1], C[c, C_FF + 2]
            fmag = math.sqrt(fx * fx + fy * fy + fz * fz)
            need = -(fx * C[c, C_HELD] + fy * C[c, C_HELD + 1] + fz * C[c, C_HELD + 2])
            if not planar and need > 0:
                need = fmag
            if need <= force_tol and not (CI[c, CI_FLIPPED] and need > -force_tol):
                CI[c, CI_MODE] = BAND
                changed = True
            elif fmag >= cap(C, CI, c) - force_tol:
                CI[c, CI_MODE] = SLIDE
                changed = True
            if not planar and fmag > 0 and CI[c, CI_MODE] != BAND:
                C[c, C_HELD], C[c, C_HELD + 1], C[c, C_HELD + 2] = -fx / fmag, -fy / fmag, -fz / fmag
        if not changed:
            solved = True
            break
    # Stuck slips onto the edge along their held direction; in 3D an edge contact that slides on
    # starts along its hold force's reverse: its slip is turned there with the stuck ones.
    turned = False
    for c in range(nc):
        if not planar and CI[c, CI_EDGE] == 1 and CI[c, CI_MODE] == SLIDE:
            CI[c, CI_MODE] = STICK
            CI[c, CI_EDGE] = 2
            turned = True
    work, ok = settle(X, C, CI, na, nc, stuck, A, b, fl, NO if solved and not turned else YES)
    for c in range(nc):
        if CI[c, CI_EDGE] == 2:
            CI[c, CI_MODE] = SLIDE
    # The friction its last solve left (C_FF, X_F, X_L) is this state's unless settling moved a
    # slip by more than a step's drift: a flip moves one by 2 eps (a mode value by 3e-8 in the break).
    return work, ok, turned, solved and not turned and not flipped_any


@jit_inline
def flips(C, CI, E, nc, c, h, omega, scale):
    """Whether stuck contact c's hold force, come to zero in a trial of h (from above: E_V0 and
    E_V1 its values at the trial's ends), crosses the band quickly enough to be taken as the
    impulse that flips its slip to the band's other edge, at the trial's end: the bodies that
    impulse moves by 2 eps over the crossing's length and over how late the trial's end is
    (both from the line through the two values) stray, times omega (FLIP_SAFETY over), within
    FLIP_SHARE of the event tolerance as a speed (EDGE_TOL scale: the mode values' unit)."""
    k = nc + c
    v0, v1 = E[k, E_V0], E[k, E_V1]
    if CI[c, CI_MODE] != STICK or not (v0 > MODE_TOL and v1 <= MODE_TOL and E[c, E_V1] > MODE_TOL):
        return False
    rate = (v0 - v1) / h * scale / STICK_SCALE  # of the slip's acceleration
    crossing = 2.0 * math.sqrt(C[c, C_EPS] / rate)
    late = h * max(-v1, 0.0) / (v0 - v1)
    return FLIP_SAFETY * omega * C[c, C_EPS] * (crossing + 2.0 * late) <= FLIP_SHARE * EDGE_TOL * scale
