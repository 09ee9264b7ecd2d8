"""The tangential spring in 3D as a continuous law, integrated by scipy's DOP853: every body, each
contact's stretch a vector state, each mode change (the cap reached, a slip ending, a contact's
start and end) a located event. Written from the law's statement (docs/method.md, "The spring
in 3D"), not from any kernel: the reference the DEM kernel's 3D spring converges to
(tests/engine/dem/test_tangential.py).

The law is the DEM kernel's per-step law (collide/engine/dem/tangential.py) taken to a vanishing
step, for a contact without a tangential dashpot (restitution 1):

* stick: the stretch xi (in the tangent plane) follows the slip and turns with the normal without
  turning about it, xi' = v_t - (xi . n') n (the per-step projection and rescale into the new
  tangent plane tends to this: it removes xi . dn, and keeps the length to second order); the
  force on i is -k_t xi.
* slide: the force is the cap mu F_n along the trial force -k_t xi, the stretch the one that holds
  it, xi = c xi^ (c = mu F_n / k_t): its direction follows the slip's component across it,
  xi' = v_t - (v_t . xi^) xi^ + c' xi^ - (xi . n') n. The slide lasts while the slip pushes the
  stretch past the cap, xi^ . v_t - c' > 0; its end is an event.

A contact's energy: (1/2) k_t |xi|^2 with k_t constant (the linear spring), the slide dissipating
cap (xi^ . v_t - c') (carried as a state, so the balance is checked at the run's end)."""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from collide.accuracy import speed_scale
from collide.model import TABLE_ESTAR, TABLE_K, TABLE_KTR, TABLE_MU, TABLE_REST, compile_scenes

OFF, STUCK, SLIPPING = 0, 1, 2
# The longest step, as a share of the run: far below the shortest contact of the scenes here
# (about 1 ms of 40-60 ms; a grazing one shorter, and of as little effect).
MAX_SHARE = 2.5e-4


def _event(value, direction):
    def event(_, y):
        return value(y)

    event.terminal, event.direction = True, direction
    return event


class Spring3D:
    """One scene's bodies and contacts, and the law's pieces at a state y = (s, v, w, xi, work)."""

    def __init__(self, scene):
        model, state = compile_scenes([scene])
        self.n, self.hertz = model.n_bodies, bool(model.hertz)
        self.dim = int(state.s[0].shape[1])
        self.m, self.r, self.inertia = model.mass[0], model.radius[0], model.inertia[0]

        def pad(a):
            return np.pad(np.asarray(a, float), ((0, 0), (0, 3 - self.dim)))

        self.points, self.normals = pad(model.wall_point), pad(model.wall_normal)
        g = np.zeros(3) if model.gravity is None else np.asarray(model.gravity[0], float)
        self.gravity = np.pad(g, (0, 3 - g.size))
        mat = model.material[0]
        self.contacts = []
        for i in range(self.n):
            for j in list(range(i + 1, self.n)) + [-1 - w for w in range(len(self.points))]:
                row = model.pair_table[0, mat[i], mat[j]] if j >= 0 else model.wall_table[0, mat[i]]
                if row[TABLE_REST] < 1.0:
                    raise ValueError("the 3D reference takes undamped contacts (restitution 1)")
                rstar = self.r[i] * self.r[j] / (self.r[i] + self.r[j]) if j >= 0 else self.r[i]
                self.contacts.append((i, j, row[TABLE_K], row[TABLE_MU], row[TABLE_ESTAR], row[TABLE_KTR], rstar))
        self.nk = len(self.contacts)
        s, v, w = state.s[0], state.v[0], state.w[0]
        w3 = np.zeros((self.n, 3))
        if self.dim == 2:
            w3[:, 2] = w[:, 0]
        else:
            w3[:] = w
        self.y0 = np.concatenate((pad(s).ravel(), pad(v).ravel(), w3.ravel(), np.zeros(3 * self.nk + 1)))
        self.mode = [OFF] * self.nk

    def split(self, y):
        n = self.n
        return (y[:3 * n].reshape(n, 3), y[3 * n:6 * n].reshape(n, 3), y[6 * n:9 * n].reshape(n, 3),
                y[9 * n:9 * n + 3 * self.nk].reshape(self.nk, 3))

    def geometry(self, y, c):
        """(delta, delta', n, n', v_t, l_i, l_j) of contact c: n from i towards j (or the wall)."""
        i, j = self.contacts[c][:2]
        s, v, w, _ = self.split(y)
        r = self.r
        if j >= 0:
            d = s[j] - s[i]
            dist = float(np.linalg.norm(d))
            nrm = d / dist
            u = v[j] - v[i]
            turn = (u - np.dot(u, nrm) * nrm) / dist
            delta = r[i] + r[j] - dist
            li, lj = r[i] - 0.5 * delta, r[j] - 0.5 * delta
            rel = v[i] - v[j] + li * np.cross(w[i], nrm) + lj * np.cross(w[j], nrm)
            closing = float(np.dot(v[i] - v[j], nrm))
        else:
            p, big = self.points[-1 - j], self.normals[-1 - j]
            nrm, turn = -big, np.zeros(3)
            delta = r[i] - float(np.dot(s[i] - p, big))
            li, lj = r[i] - delta, 0.0
            rel = v[i] + li * np.cross(w[i], nrm)
            closing = float(np.dot(v[i], nrm))
        return delta, closing, nrm, turn, rel - np.dot(rel, nrm) * nrm, li, lj

    def law(self, y, c):
        """(F_n, cap, k_t, c = cap / k_t, c', the tangential force on i)."""
        _, _, k, mu, estar, ratio, rstar = self.contacts[c]
        delta, rate, _, _, _, _, _ = self.geometry(y, c)
        dp = max(delta, 0.0)
        if self.hertz:
            kn = 2.0 * estar * math.sqrt(rstar * dp)
            fn = 4.0 / 3.0 * estar * math.sqrt(rstar * dp) * dp
            reach, share = mu * dp * 2.0 / 3.0 / ratio, 2.0 / 3.0
        else:
            kn, fn = k, k * delta
            reach, share = mu * dp / ratio, 1.0
        cap, kt = mu * max(fn, 0.0), ratio * kn
        xi = self.split(y)[3][c]
        if self.mode[c] == SLIPPING:
            size = float(np.linalg.norm(xi))
            force = -cap * xi / size if size > 0.0 else np.zeros(3)
        else:
            force = -kt * xi
        return fn, cap, kt, reach, mu * rate * share / ratio, force

    def slide_value(self, y, c):
        """> 0 while a slide lasts: the slip along the stretch past the cap's own change, xi^ . v_t - c'."""
        xi = self.split(y)[3][c]
        size = float(np.linalg.norm(xi))
        ve = self.geometry(y, c)[4]
        return (float(np.dot(xi, ve)) / size if size > 0.0 else 0.0) - self.law(y, c)[4]

    def rhs(self, _, y):
        n = self.n
        f = np.zeros_like(y)
        _, v, _, xis = self.split(y)
        f[:3 * n] = v.ravel()
        acc = np.tile(self.gravity, (n, 1))
        torque = np.zeros((n, 3))
        for c in range(self.nk):
            if self.mode[c] == OFF:
                continue
            i, j = self.contacts[c][:2]
            _, _, nrm, turn, vt, li, lj = self.geometry(y, c)
            fn, cap, _, reach, rate, ft = self.law(y, c)
            force = -fn * nrm + ft
            acc[i] += force / self.m[i]
            torque[i] += li * np.cross(nrm, ft)
            if j >= 0:
                acc[j] -= force / self.m[j]
                torque[j] += lj * np.cross(nrm, ft)
            xi = xis[c]
            transport = -np.dot(xi, turn) * nrm
            rows = slice(9 * n + 3 * c, 9 * n + 3 * c + 3)
            if self.mode[c] == STUCK:
                f[rows] = vt + transport
            else:
                size = float(np.linalg.norm(xi))
                unit = xi / size if size > 0.0 else xi
                along = float(np.dot(vt, unit))
                f[rows] = vt - along * unit + rate * unit + transport
                f[-1] += cap * (along - rate)
        f[3 * n:6 * n] = acc.ravel()
        f[6 * n:9 * n] = (torque / self.inertia[:, None]).ravel()
        return f

    def energy(self, y):
        """Kinetic, rotational, gravitational, normal and tangential springs' energy, and the slides'
        work dissipated so far (linear contacts: k_t constant)."""
        s, v, w, xis = self.split(y)
        e = 0.5 * float(np.sum(self.m[:, None] * v * v)) + 0.5 * float(np.sum(self.inertia[:, None] * w * w))
        e -= float(np.sum(self.m[:, None] * s * self.gravity))
        for c in range(self.nk):
            if self.mode[c] == OFF:
                continue
            delta = self.geometry(y, c)[0]
            k, ratio = self.contacts[c][2], self.contacts[c][5]
            e += 0.5 * k * delta * delta + 0.5 * ratio * k * float(np.dot(xis[c], xis[c]))
        return e, float(y[-1])

    def events(self):
        out = []
        for c in range(self.nk):
            if self.mode[c] == OFF:
                out.append((_event(lambda y, c=c: self.geometry(y, c)[0], 1.0), c, "start"))
                continue
            out.append((_event(lambda y, c=c: self.geometry(y, c)[0], -1.0), c, "end"))
            if self.mode[c] == STUCK:
                out.append((_event(lambda y, c=c: self.law(y, c)[1] - float(np.linalg.norm(self.law(y, c)[5])),
                                   -1.0), c, "cap"))
            else:
                out.append((_event(lambda y, c=c: self.slide_value(y, c), -1.0), c, "slip ends"))
        return out

    def start(self, y, c):
        """A contact begins: no stretch; at touching the spring and the cap both vanish, their
        rates decide (the stretch grows as v_t, the cap as c'): it slides, its stretch along the
        slip, where |v_t| > c'."""
        rows = slice(9 * self.n + 3 * c, 9 * self.n + 3 * c + 3)
        vt = self.geometry(y, c)[4]
        size = float(np.linalg.norm(vt))
        if size > self.law(y, c)[4]:
            self.mode[c] = SLIPPING
            y[rows] = 1e-300 * vt / size  # its direction only: the force takes the cap along it
        else:
            self.mode[c] = STUCK
            y[rows] = 0.0

    def to_cap(self, y, c, t_end):
        """The cap reached: the stretch held at c along its way; it slides unless the slip then
        runs back within the cap (the slide's value not positive)."""
        rows = slice(9 * self.n + 3 * c, 9 * self.n + 3 * c + 3)
        reach = self.law(y, c)[3]
        xi = y[rows]
        y[rows] = reach * xi / float(np.linalg.norm(xi))
        self.mode[c] = SLIPPING
        if self.slide_value(y, c) <= 0.0:
            self.mode[c] = STUCK

    def run(self, t_end, rtol=1e-12, scale=1.0, log=None):
        """The state at t_end; each event into `log` (time, contact, what, mode after)."""
        y, t = self.y0.copy(), 0.0
        for _ in range(10000):
            evs = self.events()
            # In flight the motion is a polynomial DOP853 follows without error, and its step grew
            # past a whole contact (two spheres that met in DEM flew through each other here): a
            # contact's start is seen only at a step's end, so no step spans more than MAX_SHARE.
            sol = solve_ivp(self.rhs, (t, t_end), y, method="DOP853", rtol=rtol, atol=rtol * 1e-6 * scale,
                            events=[ev for ev, _, _ in evs], max_step=MAX_SHARE * t_end)
            assert sol.status in (0, 1), sol.message
            if sol.status == 0:
                return sol.y[:, -1]
            t, k = min((sol.t_events[k][0], k) for k in range(len(evs)) if len(sol.t_events[k]))
            y = sol.y_events[k][0].copy()
            _, c, what = evs[k]
            if what == "start":
                self.start(y, c)
            elif what == "end":
                self.mode[c] = OFF
                y[9 * self.n + 3 * c:9 * self.n + 3 * c + 3] = 0.0
            elif what == "cap":
                self.to_cap(y, c, t_end)
            elif what == "slip ends":
                self.mode[c] = STUCK
            if log is not None:
                log.append((t, c, what, self.mode[c]))
        raise AssertionError("too many events")


def reference(scene, rtol=1e-12, log=None, keep=None):
    """The scene's final velocities and spins times radius in 3D (x, y, z per body: v, then w r) by
    DOP853; `keep` gets the Spring3D and its final state."""
    law = Spring3D(scene)
    y = law.run(float(scene.duration), rtol=rtol, scale=max(speed_scale(scene), 1e-300), log=log)
    if keep is not None:
        keep.extend((law, y))
    _, v, w, _ = law.split(y)
    return np.concatenate((v.ravel(), (w * law.r[:, None]).ravel()))


def _scene3d(body, ratio, mu, model, duration):
    """test_spring's scene of these bodies (undamped), in 3D (imported here: it imports this module)."""
    from tests.engine.event.test_spring import _scene

    raw = _scene(body, ratio, mu, model, 1.0, duration)
    raw["dim"], raw["name"] = 3, "rub3"
    return raw


def cluster3d(ratio=0.5, mu=0.3, model="linear", spin=(3.0, -5.0, 8.0), tilt=0.3, offset=(-0.004, 0.003),
              back=(-0.5, 0.1, 0.2), duration=0.06):
    """Three spheres out of a plane, the first thrown at the second off-centre and spun about all
    axes, the third coming back: each pair's contact rubs, its normal turning out of any plane."""
    r = 0.01
    body = [{"name": "a", "mass": 0.01, "radius": r, "position": [0.0, 0.0, 0.0], "velocity": [1.0, 0.0, 0.1],
             "spin": list(spin)},
            {"name": "b", "mass": 0.01, "radius": r,
             "position": [0.03, 0.03 * math.sin(tilt), 0.03 * math.sin(0.7 * tilt)]},
            {"name": "c", "mass": 0.012, "radius": r, "position": [0.06, offset[0], offset[1]], "velocity": list(back)}]
    return _scene3d(body, ratio, mu, model, duration)


def floor3d(ratio=0.5, mu=0.3, model="linear", spin=(20.0, -10.0, 5.0), drop=(1.0, 0.4, -0.3), duration=0.04):
    """Two spheres over a floor under gravity, the first thrown down at it and at the second, spun
    about all axes: they rub on the floor and on each other."""
    r = 0.01
    body = [{"name": "a", "mass": 0.01, "radius": r, "position": [0.0, 0.0, r + 0.006], "velocity": list(drop),
             "spin": list(spin)},
            {"name": "b", "mass": 0.012, "radius": r, "position": [0.03, 0.012, r + 0.003]}]
    raw = _scene3d(body, ratio, mu, model, duration)
    raw["wall"] = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}]
    raw["gravity"] = [0.0, 0.0, -9.81]
    return raw


def case3d(seed):
    """A random undamped 3D case: cluster or floor, linear or Hertz, k_t / k_n 0.1-1.5, mu
    0.02-0.9, spins about all axes, out-of-plane angles and speeds."""
    rng = np.random.default_rng(seed)
    law = {"ratio": float(rng.uniform(0.1, 1.5)), "mu": float(rng.uniform(0.02, 0.9)),
           "model": "hertz" if rng.random() < 0.5 else "linear",
           "spin": tuple(float(x) for x in rng.uniform(-40.0, 40.0, 3))}
    if rng.random() < 0.35:
        return floor3d(drop=(float(rng.uniform(0.3, 1.5)), float(rng.uniform(-0.5, 0.5)),
                             float(rng.uniform(-1.0, -0.1))), **law)
    return cluster3d(tilt=float(rng.uniform(-0.6, 0.6)), offset=tuple(float(x) for x in rng.uniform(-0.012, 0.012, 2)),
                     back=tuple(float(x) for x in rng.uniform(-0.5, 0.3, 3)), **law)
