#!/usr/bin/env python3
"""Units made apart from gyrobench's twin, for `gyrobench diagnose` to be
judged on (docs/diagnosis.md, "Units made apart from the twin").

One RL-16-like unit per seed, its study thermal cycle and orientation run
written as interchange CSV with its site file. Written from the design
notes (frames, Earth rate, field, noise, model 4, the two procedures) and
not from the twin's code: its own RC thermal networks of 2-4 nodes (a
block carrying both sensors or two blocks, a mount beside the case's own
path to the air, a block's conductance to the case raised while the
sensitive axis is horizontal), integrated exactly; a chamber that trails
its set point and cycles, read by a sensor with gain and offset errors;
sensors with offsets, noise and quantisation; the rate as whole pulses of
Earth rate on the true axis, model 4, a turn-on bias, white noise and a
wander of three Gauss-Markov processes. The orientation run's records
start after its warm-up, as a lab's export has them.

usage: independent_units.py --seed N --case CASE --out DIR [--factor F]
  CASE: null | hysteresis | thermal_lag | g_sensitivity | magnetic_sensitivity |
        axis_misalignment | pair_g_hyst | pair_mag_lag | step | sine
  --factor: size of a withheld effect in units of the unit's noise of 60 s means
            (default: uniform 2..4, drawn from the seed)
  --thermal-effect EFFECT: thermal physics the twin's network does not have
            (sensor_lag | sensor_gain | orientation_coupling | air_path |
            conductance_temperature), drawn from a stream of its own so the
            unit is otherwise the one the seed gives without it
Writes DIR/cycle.csv, DIR/orient.csv, DIR/site.toml, DIR/truth.json.
"""
import argparse
import json
import math
import os

import numpy as np

W_E = 15.0411  # deg/h
D2R = math.pi / 180.0
ARCMIN = D2R / 60.0

# ---------------------------------------------------------------- procedures
# thermal cycle: (label, duration_s, chamber setpoint command at the start or None)
CYCLE = [
    ("self_heating", 1800.0, None),
    ("ramp_to_hot", 1800.0, 50.0),
    ("soak_hot", 3600.0, None),
    ("ramp_to_cold", 5400.0, -40.0),
    ("soak_cold", 5400.0, None),
    ("ramp_back", 3600.0, 20.0),
    ("soak_end", 1800.0, None),
]
CYCLE_ORIENT = (0.0, 90.0, 0.0)  # axis up
ORIENT_POS = [
    ("az000", (0.0, 90.0, 0.0)),
    ("az090", (90.0, 90.0, 0.0)),
    ("az180", (180.0, 90.0, 0.0)),
    ("az270", (270.0, 90.0, 0.0)),
    ("roll000", (90.0, 0.0, 0.0)),
    ("roll090", (90.0, 0.0, 90.0)),
    ("roll180", (90.0, 0.0, 180.0)),
    ("roll270", (90.0, 0.0, -90.0)),
    ("tilt55", (90.0, 35.0, 0.0)),
]
RAMP = 1.0 / 60.0  # degC/s
# Seconds per position of the orientation run (the first 300 s unrecorded).
POS_S = 1500


def r_nb(yaw, pitch, roll):
    y, p, r = yaw * D2R, pitch * D2R, roll * D2R
    cz, sz, cy, sy, cx, sx = math.cos(y), math.sin(y), math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]])
    Ry = np.array([[cy, 0, sy], [0, 1.0, 0], [-sy, 0, cy]])
    Rx = np.array([[1.0, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


def timeline(kind):
    """Per-second arrays for one run: t (interval start), setpoint, orientation index,
    step label (None where not recorded)."""
    if kind == "cycle":
        total = int(sum(d for _, d, _ in CYCLE))
        sp = np.empty(total)
        labels = np.empty(total, dtype=object)
        ori = np.zeros(total, dtype=int)
        cur, target, t0 = 20.0, 20.0, 0
        for lab, dur, cmd in CYCLE:
            n = int(dur)
            if cmd is not None:
                target = cmd
            for k in range(n):
                step = RAMP if target > cur else -RAMP
                if abs(target - cur) <= RAMP:
                    cur = target
                else:
                    cur += step
                sp[t0 + k] = cur
            labels[t0:t0 + n] = lab
            t0 += n
        orients = [CYCLE_ORIENT]
    else:
        total = 1800 + 9 * POS_S
        sp = np.full(total, 20.0)
        labels = np.empty(total, dtype=object)
        ori = np.zeros(total, dtype=int)
        orients = []
        t0 = 1800
        for i, (lab, o) in enumerate(ORIENT_POS):
            orients.append(o)
            ori[t0:t0 + POS_S] = i
            labels[t0 + 300:t0 + POS_S] = lab
            t0 += POS_S
    return np.arange(total, dtype=float), sp, ori, orients, labels


# ---------------------------------------------------------------- thermal network
class Network:
    """Lumped RC network: nodes with capacities, conductances between nodes and to air,
    constant heat input after power-on. States in degC."""

    def __init__(self, rng):
        self.variant = int(rng.integers(2, 5))  # 2, 3 or 4 nodes
        tau_c = rng.uniform(600, 3000)
        Cc = 1.0
        Gca = Cc / tau_c
        names = ["case"]
        C = [Cc]
        Gair = [Gca]
        edges = []  # (i, j, G)
        P = [0.0]
        rise_total = rng.uniform(0.0, 5.0)  # block self-heating rise, degC (approx.)
        if self.variant >= 3:
            names += ["block1", "block2"]
            tb1, tb2 = rng.uniform(100, 2000), rng.uniform(100, 2000)
            Cb1, Cb2 = Cc * rng.uniform(0.15, 0.8), Cc * rng.uniform(0.15, 0.8)
            edges += [(1, 0, Cb1 / tb1), (2, 0, Cb2 / tb2)]
            t12 = rng.uniform(200, 3000)
            edges += [(1, 2, min(Cb1, Cb2) / t12)]
            C += [Cb1, Cb2]
            Gair += [0.0, 0.0]
            split = rng.uniform(0.55, 0.9)  # discharge heat unequally spread
            P += [split, 1.0 - split]
        else:
            names += ["block"]
            tb = rng.uniform(100, 2000)
            Cb = Cc * rng.uniform(0.15, 0.8)
            edges += [(1, 0, Cb / tb)]
            C += [Cb]
            Gair += [0.0]
            P += [1.0]
        if self.variant == 4:
            names += ["mount"]
            tm = rng.uniform(300, 1500)
            Cm = Cc * rng.uniform(0.5, 2.0)
            # mount tied to the chamber air and to the case; case keeps some direct convection
            frac = rng.uniform(0.3, 0.7)
            Gair[0] = Gca * (1 - frac)
            edges += [(0, len(names) - 1, Gca * frac * 2.0)]
            C += [Cm]
            Gair += [Cm / tm]
            P += [0.0]
        self.names = names
        self.C = np.array(C)
        self.Gair = np.array(Gair)
        self.edges = edges
        n = len(names)
        # electronics heat on the case: a fraction of the discharge heat
        P = np.array(P)
        P[0] = rng.uniform(0.0, 0.4)
        self.P_shape = P
        self.n = n
        # scale power so that the block-sensor steady rise over air is rise_total
        L = self.laplacian(1.0)
        ss = np.linalg.solve(L, P)
        self.P = P * (rise_total / max(ss[1], 1e-9))
        self.rise_total = rise_total
        # orientation-dependent internal convection: block1-case conductance factor when horizontal
        self.conv = rng.uniform(0.0, 0.2) if rng.random() < 0.6 else 0.0
        # sensors
        if self.variant >= 3:
            self.t1_w = np.eye(n)[1]
            self.t2_w = np.eye(n)[2]
        else:
            a = rng.uniform(0.5, 0.9)
            self.t1_w = np.eye(n)[1]
            self.t2_w = a * np.eye(n)[1] + (1 - a) * np.eye(n)[0]
            self.t2_mix = a
        self.tk_w = np.eye(n)[0]
        self._cache = {}

    def laplacian(self, conv_factor, air_factor=1.0):
        n = len(self.C)
        gair = self.Gair.copy()
        gair[0] *= air_factor
        L = np.diag(gair)
        for k, (i, j, g) in enumerate(self.edges):
            if k == 0:
                g = g * conv_factor
            L[i, i] += g
            L[j, j] += g
            L[i, j] -= g
            L[j, i] -= g
        return L

    def discrete(self, conv_factor, dt=1.0, air_factor=1.0):
        key = (round(conv_factor, 9), round(air_factor, 9))
        if key in self._cache:
            return self._cache[key]
        L = self.laplacian(conv_factor, air_factor)
        Cs = np.sqrt(self.C)
        S = -(L / Cs[:, None]) / Cs[None, :]  # symmetric similar of A = -C^-1 L
        lam, V = np.linalg.eigh(S)
        Ad = (V * np.exp(lam * dt)) @ V.T
        Ad = (Ad / Cs[:, None]) * Cs[None, :]
        A = -L / self.C[:, None]
        # inputs: air temperature (through Gair) and power
        gair = self.Gair.copy()
        gair[0] *= air_factor
        B = np.column_stack([gair / self.C, self.P / self.C])
        Bd = np.linalg.solve(A, (Ad - np.eye(len(self.C))) @ B)
        out = (A, B, Ad, Bd, -1.0 / lam)
        self._cache[key] = out
        return out

    def time_constants(self):
        return sorted(self.discrete(1.0)[4].tolist())

    def simulate(self, air, conv_factors, T0, air_factors=None):
        """ZOH exact stepping at 1 s. Returns node temperatures at interval midpoints
        (approximated by the average of both ends) and the node derivatives.
        `air_factors` scale the case's conductance to the air step by step."""
        N = len(air)
        X = np.empty((N, self.n))
        Xd = np.empty((N, self.n))
        x = np.full(self.n, T0, dtype=float)
        for k in range(N):
            af = 1.0 if air_factors is None else air_factors[k]
            A, B, Ad, Bd, _ = self.discrete(conv_factors[k], air_factor=af)
            u = np.array([air[k], 1.0])
            xn = Ad @ x + Bd @ u
            X[k] = 0.5 * (x + xn)
            Xd[k] = A @ X[k] + B @ u
            x = xn
        return X, Xd


def play(x, r, y0):
    y = np.empty_like(x)
    cur = y0
    for k in range(len(x)):
        cur = max(x[k] - r, min(x[k] + r, cur))
        y[k] = cur
    return y


def lag(x, tau, y0):
    a = math.exp(-1.0 / tau)
    y = np.empty_like(x)
    cur = y0
    for k in range(len(x)):
        cur = a * cur + (1 - a) * x[k]
        y[k] = cur
    return y


def gauss_markov(rng, n, tau, sigma):
    a = math.exp(-1.0 / tau)
    e = rng.normal(0.0, sigma * math.sqrt(1 - a * a), n)
    y = np.empty(n)
    cur = rng.normal(0.0, sigma)
    for k in range(n):
        cur = a * cur + e[k]
        y[k] = cur
    return y


def quant(x, q):
    return np.round(x / q) * q


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--case", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--factor", type=float, default=None)
    ap.add_argument("--unsoaked", type=float, default=0.0,
                    help="max |unit - air| at power-on, degC (0: soaked at the air temperature)")
    ap.add_argument("--physical", action="store_true",
                    help="keep the withheld effects at their drawn physical sizes (the ranges drawn), no rescaling to factor x sigma60")
    ap.add_argument("--step-run", choices=["cycle", "orient"], default=None,
                    help="put the step in this run (default: drawn from the seed)")
    ap.add_argument("--ool-scaled", action="store_true",
                    help="size the step / sine like a withheld effect (factor x sigma60 after projection) "
                         "instead of the fixed 0.03 / 0.02 deg/h")
    ap.add_argument("--low-latitude", action="store_true",
                    help="a lab near the equator: latitude within 12 deg of it, the thermal cycle with the "
                         "axis horizontal pointing north, the orientation run's four azimuths with the axis "
                         "horizontal, its four rolls about the axis pointing north, the 55 deg tilt toward north")
    ap.add_argument("--thermal-effect", default=None,
                    choices=["sensor_lag", "sensor_gain", "orientation_coupling", "air_path",
                             "conductance_temperature"],
                    help="thermal physics beyond the twin's network form (see the module's docstring)")
    ap.add_argument("--long", action="store_true",
                    help="runs of a lab's own length: a 9 h thermal cycle (longer soaks) and a 7 h "
                         "orientation run (2600 s per position) instead of 6.5 h and 4.25 h")
    a = ap.parse_args()
    if a.long:
        global CYCLE, POS_S
        CYCLE = [
            ("self_heating", 1800.0, None),
            ("ramp_to_hot", 2400.0, 50.0),
            ("soak_hot", 5400.0, None),
            ("ramp_to_cold", 5400.0, -40.0),
            ("soak_cold", 7200.0, None),
            ("ramp_back", 3600.0, 20.0),
            ("soak_end", 6600.0, None),
        ]
        POS_S = 2600
    if a.low_latitude:
        global CYCLE_ORIENT, ORIENT_POS
        CYCLE_ORIENT = (0.0, 0.0, 0.0)
        ORIENT_POS = [
            ("az000", (0.0, 0.0, 0.0)),
            ("az090", (90.0, 0.0, 0.0)),
            ("az180", (180.0, 0.0, 0.0)),
            ("az270", (270.0, 0.0, 0.0)),
            ("roll000", (0.0, 0.0, 0.0)),
            ("roll090", (0.0, 0.0, 90.0)),
            ("roll180", (0.0, 0.0, 180.0)),
            ("roll270", (0.0, 0.0, -90.0)),
            ("tilt55", (0.0, 35.0, 0.0)),
        ]
    rng = np.random.default_rng(a.seed)
    os.makedirs(a.out, exist_ok=True)
    truth = {"seed": a.seed, "case": a.case}

    # ---------------- site
    lat = float(rng.uniform(-60, 65))
    if a.low_latitude:
        lat = lat / 65.0 * 12.0
    lon = float(rng.uniform(-180, 180))
    height = float(rng.uniform(0, 1500))
    B0 = rng.uniform(28, 33)  # equatorial dipole field, uT
    maglat = lat + rng.uniform(-8, 8)
    Bh = B0 * math.cos(maglat * D2R)
    Bd = 2 * B0 * math.sin(maglat * D2R)
    dec = rng.uniform(-15, 15) * D2R
    Bned = np.array([Bh * math.cos(dec), Bh * math.sin(dec), Bd])
    phi = lat * D2R
    w_n = W_E * np.array([math.cos(phi), 0.0, -math.sin(phi)])
    g_n = np.array([0.0, 0.0, 1.0])
    with open(os.path.join(a.out, "site.toml"), "w") as f:
        f.write("[site]\n")
        f.write(f"latitude_deg = {lat:.4f}\nlongitude_deg = {lon:.4f}\nheight_m = {height:.1f}\n")
        f.write("magnetic_field_ned_ut = [%.2f, %.2f, %.2f]\n" % tuple(Bned))
    truth["site"] = {"lat": lat, "B_ned": Bned.tolist()}

    # ---------------- unit
    net = Network(rng)
    truth["thermal"] = {"variant_nodes": net.n, "names": net.names, "time_constants_s": net.time_constants(),
                        "rise_block_c": net.rise_total, "conv": net.conv}
    # thermal physics beyond the twin's form, from a stream of its own
    th = {}
    if a.thermal_effect:
        trng = np.random.default_rng(a.seed + 7_000_003)
        sign = lambda: float(trng.choice([-1.0, 1.0]))  # noqa: E731
        if a.thermal_effect == "sensor_lag":
            th = dict(sensor=str(trng.choice(["t1", "t2", "tk"])), tau_s=float(trng.uniform(90, 600)))
        elif a.thermal_effect == "sensor_gain":
            th = dict(sensor=str(trng.choice(["t1", "t2", "tk"])), gain_error=float(trng.uniform(0.01, 0.03)) * sign())
        elif a.thermal_effect == "orientation_coupling":
            # block 1's conductance to the case grows with gravity along a body axis
            # other than the sensitive axis (x)
            th = dict(axis=int(trng.choice([1, 2])), k=float(trng.uniform(0.3, 0.8)))
        elif a.thermal_effect == "air_path":
            # block 1 sees the air directly as well as through the case
            th = dict(tau_s=float(trng.uniform(2000, 12000)))
            net.Gair[1] = net.C[1] / th["tau_s"]
            net._cache = {}
        elif a.thermal_effect == "conductance_temperature":
            th = dict(per_c=float(trng.uniform(0.004, 0.01)) * sign())
        th["effect"] = a.thermal_effect
    truth["thermal_effect"] = th
    tau_ch = rng.uniform(60, 120)
    ch_gain, ch_off = 1 + rng.uniform(-0.005, 0.005), rng.uniform(-0.3, 0.3)
    ch_osc_amp, ch_osc_per = rng.uniform(0, 0.08), rng.uniform(300, 900)
    truth["chamber"] = dict(tau_s=tau_ch, sensor_gain=ch_gain, sensor_offset_c=ch_off, cycling_amp_c=ch_osc_amp,
                            cycling_period_s=ch_osc_per)
    sens = {}
    for s in ("t1", "t2", "tk"):
        sens[s] = (rng.uniform(-0.3, 0.3), rng.uniform(0.005, 0.05), float(rng.choice([0.01, 0.02, 0.05])))
    truth["sensors"] = sens

    K1 = rng.uniform(0.01, 0.05) * rng.choice([-1, 1])
    K2 = rng.uniform(-0.001, 0.001)
    K3 = rng.uniform(5, 50) * rng.choice([-1, 1])
    K4 = rng.uniform(-0.005, 0.005)
    K5 = rng.uniform(0.3, 0.7) * rng.choice([-1, 1])
    tau_w = rng.uniform(600, 2000)
    b0 = rng.uniform(-1.0, 1.0)
    arw = rng.uniform(0.002, 0.006)
    sig1 = arw * 60.0
    wander = rng.uniform(0.002, 0.005)
    lsb = float(rng.choice([0.1, 0.2, 0.25, 0.5]))  # arcsec per pulse
    sig60 = math.sqrt(sig1 ** 2 / 60 + wander ** 2)
    truth["model4"] = dict(K1=K1, K2=K2, K3=K3, K4=K4, K5=K5, tau_w=tau_w, b0=b0)
    truth["noise"] = dict(arw=arw, sigma1_dph=sig1, wander_dph=wander, lsb_arcsec=lsb, sigma60_dph=sig60)

    factor = a.factor if a.factor is not None else float(rng.uniform(2, 4))
    # effect parameters (sizes rescaled below to `factor` x sigma60)
    eff = {}
    case = a.case
    wanted = []
    if case in ("hysteresis", "pair_g_hyst"):
        wanted.append("hysteresis")
        eff["hysteresis"] = dict(width_c=rng.uniform(2, 15), on=str(rng.choice(["case", "block"])),
                                 amp=rng.uniform(0.05, 0.15) * rng.choice([-1, 1]))
    if case in ("thermal_lag", "pair_mag_lag"):
        wanted.append("thermal_lag")
        eff["thermal_lag"] = dict(tau_s=rng.uniform(1200, 7200), c=rng.uniform(0.002, 0.01) * rng.choice([-1, 1]))
    if case in ("g_sensitivity", "pair_g_hyst"):
        wanted.append("g_sensitivity")
        m, ang = rng.uniform(0.02, 0.1), rng.uniform(0, 2 * math.pi)
        eff["g_sensitivity"] = dict(k=[0.0, m * math.cos(ang), m * math.sin(ang)])
    if case in ("magnetic_sensitivity", "pair_mag_lag"):
        wanted.append("magnetic_sensitivity")
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        eff["magnetic_sensitivity"] = dict(k=(v * rng.uniform(0.001, 0.004)).tolist())
    if case == "axis_misalignment":
        wanted.append("axis_misalignment")
        eff["axis_misalignment"] = dict(tilt_arcmin=rng.uniform(5, 30), dir_rad=rng.uniform(0, 2 * math.pi))
    if case == "step":
        eff["step"] = dict(run=str(rng.choice(["cycle", "orient"])), frac=rng.uniform(0.3, 0.7),
                           size=0.03 * rng.choice([-1, 1]))
        if a.step_run:
            eff["step"]["run"] = a.step_run
    if case == "sine":
        eff["sine"] = dict(period_s=rng.uniform(40, 120) * 60, amp=0.02, phase=[rng.uniform(0, 6.283) for _ in range(2)])
    if case != "null" and not eff:
        raise SystemExit(f"unknown case {case}")

    runs = {}
    for ri, kind in enumerate(("cycle", "orient")):
        t, sp, ori, orients, labels = timeline(kind)
        N = len(t)
        # chamber air: first-order lag of the controller setpoint + small control cycling
        air = lag(sp, tau_ch, 20.0) + ch_osc_amp * np.sin(2 * math.pi * t / ch_osc_per + rng.uniform(0, 6.3))
        R = [r_nb(*o) for o in orients]
        elev = np.array([orients[i][1] for i in ori])
        conv = 1.0 + net.conv * (1.0 - np.abs(np.sin(elev * D2R)))
        if th.get("effect") == "orientation_coupling":
            g_axis = np.array([abs((r_nb(*o).T @ np.array([0.0, 0.0, 1.0]))[th["axis"]]) for o in orients])[ori]
            conv = conv * (1.0 + th["k"] * g_axis)
        air_factors = None
        if th.get("effect") == "conductance_temperature":
            air_factors = np.maximum(1.0 + th["per_c"] * (np.round(air * 2.0) / 2.0 - 20.0), 0.05)
        T0 = 20.0 + a.unsoaked * rng.uniform(-1, 1)  # unit soaked at the chamber air before power-on
        X, Xd = net.simulate(air, conv, T0, air_factors)
        T1, T2, TK = X @ net.t1_w, X @ net.t2_w, X @ net.tk_w
        dT = T1 - T2
        dTr = Xd @ net.t1_w - Xd @ net.t2_w
        tm = t + 0.5
        # earth rate on the (true) sensitive axis
        s_b = np.array([1.0, 0.0, 0.0])
        if "axis_misalignment" in eff:
            e = eff["axis_misalignment"]
            al = e["tilt_arcmin"] * ARCMIN
            s_b = np.array([math.cos(al), math.sin(al) * math.cos(e["dir_rad"]), math.sin(al) * math.sin(e["dir_rad"])])
        w_b = np.array([Rm.T @ w_n for Rm in R])[ori]
        g_b = np.array([Rm.T @ g_n for Rm in R])[ori]
        B_b = np.array([Rm.T @ Bned for Rm in R])[ori]
        earth_model = w_b[:, 0]
        earth_true = w_b @ s_b
        bias4 = K1 * dT + K2 * dT ** 2 + K3 * dTr + K4 * TK + K5 * np.exp(-tm / tau_w)
        run_off = rng.uniform(-0.03, 0.03)
        # withheld effects, unscaled
        parts = {}
        if "hysteresis" in eff:
            e = eff["hysteresis"]
            x = TK if e["on"] == "case" else 0.5 * (T1 + T2)
            r = e["width_c"] / 2
            y = play(x, r, x[0])
            parts["hysteresis"] = e["amp"] * (y - x) / r
        if "thermal_lag" in eff:
            e = eff["thermal_lag"]
            parts["thermal_lag"] = e["c"] * lag(TK, e["tau_s"], TK[0])
        if "g_sensitivity" in eff:
            parts["g_sensitivity"] = g_b @ np.array(eff["g_sensitivity"]["k"])
        if "magnetic_sensitivity" in eff:
            parts["magnetic_sensitivity"] = B_b @ np.array(eff["magnetic_sensitivity"]["k"])
        if "axis_misalignment" in eff:
            parts["axis_misalignment"] = earth_true - earth_model
        if "step" in eff and eff["step"]["run"] == kind:
            e = eff["step"]
            rec = np.flatnonzero(labels != None)  # noqa: E711
            tstep = t[rec[int(e["frac"] * len(rec))]]
            e["t_s"] = float(tstep)
            parts["step"] = np.where(t >= tstep, e["size"], 0.0)
        if "sine" in eff:
            e = eff["sine"]
            parts["sine"] = e["amp"] * np.sin(2 * math.pi * tm / e["period_s"] + e["phase"][ri])
        wand = sum(gauss_markov(rng, N, tc, wander / math.sqrt(3)) for tc in (200.0, 2000.0, 20000.0))
        white = rng.normal(0, sig1, N)
        runs[kind] = dict(t=t, tm=tm, labels=labels, ori=ori, orients=orients, air=air, T1=T1, T2=T2, TK=TK,
                          dT=dT, dTr=dTr, earth=earth_model, bias4=bias4, off=b0 + run_off, parts=parts,
                          noise=wand + white)

    # ---------------- size the withheld effects: factor x sigma60 after projecting out what
    # model 4 plus a per-run constant can absorb (robust amplitude of 60 s means)
    def recorded(kind):
        return np.flatnonzero(runs[kind]["labels"] != None)  # noqa: E711

    def design():
        cols = []
        for ri, kind in enumerate(("cycle", "orient")):
            r = runs[kind]
            idx = recorded(kind)
            m = np.column_stack([np.full(len(idx), 1.0 if ri == 0 else 0.0), np.full(len(idx), 1.0 if ri == 1 else 0.0),
                                 r["dT"][idx], r["dT"][idx] ** 2, r["dTr"][idx], r["TK"][idx],
                                 np.exp(-r["tm"][idx] / tau_w)])
            cols.append(m)
        return np.vstack(cols)

    X = design()

    def amplitude(name):
        v = np.concatenate([runs[k]["parts"].get(name, np.zeros(len(runs[k]["t"])))[recorded(k)] for k in ("cycle", "orient")])
        res = v - X @ np.linalg.lstsq(X, v, rcond=None)[0]
        # 60 s means within runs (rows are contiguous per record in each run)
        n60 = len(res) // 60
        m = res[:n60 * 60].reshape(n60, 60).mean(axis=1)
        return 0.5 * (np.percentile(m, 99) - np.percentile(m, 1)), float(np.sqrt(np.mean(res ** 2)))

    truth["effects"] = {}
    for name in wanted:
        amp0, rms0 = amplitude(name)
        scale = factor * sig60 / amp0 if amp0 > 0 and not a.physical else 1.0
        for k in ("cycle", "orient"):
            if name in runs[k]["parts"]:
                runs[k]["parts"][name] = runs[k]["parts"][name] * scale
        e = eff[name]
        if name == "hysteresis":
            e["amp"] *= scale
        elif name == "thermal_lag":
            e["c"] *= scale
        elif name in ("g_sensitivity", "magnetic_sensitivity"):
            e["k"] = [x * scale for x in e["k"]]
            e["k_norm"] = float(np.linalg.norm(e["k"]))
        elif name == "axis_misalignment":
            # rescale by re-tilting: small angle, linear in the tilt
            e["tilt_arcmin"] *= scale
        e["scale"] = scale
        e["visible_amp_dph"] = amp0 * scale
        e["visible_rms_dph"] = rms0 * scale
        e["factor"] = amp0 * scale / sig60
    for name in ("step", "sine"):
        if name in eff:
            amp0, rms0 = amplitude(name)
            if a.ool_scaled and amp0 > 0:
                scale = factor * sig60 / amp0
                for k in ("cycle", "orient"):
                    if name in runs[k]["parts"]:
                        runs[k]["parts"][name] = runs[k]["parts"][name] * scale
                eff[name]["size" if name == "step" else "amp"] *= scale
                eff[name]["scale"] = scale
                amp0, rms0 = amp0 * scale, rms0 * scale
            eff[name]["visible_amp_dph"] = amp0
            eff[name]["visible_rms_dph"] = rms0
            eff[name]["factor"] = amp0 / sig60
    truth["effects"] = eff
    truth["withheld"] = wanted

    # ---------------- outputs
    for kind, fname in (("cycle", "cycle.csv"), ("orient", "orient.csv")):
        r = runs[kind]
        N = len(r["t"])
        true_rate = r["earth"] + r["bias4"] + r["off"] + r["noise"] + sum(r["parts"].values(), np.zeros(N))
        # pulses of `lsb` arcsec; residual angle carried over (1 deg/h over 1 s = 1 arcsec)
        theta = np.cumsum(true_rate)
        counts = np.floor(theta / lsb)
        pulses = np.diff(np.concatenate([[0.0], counts]))
        rate = pulses * lsb
        meas = {}
        for s, key in (("t1", "T1"), ("t2", "T2"), ("tk", "TK")):
            off, sd, q = sens[s]
            node = r[key]
            if th.get("sensor") == s and "tau_s" in th:
                node = lag(node, th["tau_s"], node[0])
            if th.get("sensor") == s and "gain_error" in th:
                node = (1.0 + th["gain_error"]) * node
            meas[s] = quant(node + off + rng.normal(0, sd, N), q)
        ch = quant(r["air"] * ch_gain + ch_off + rng.normal(0, 0.01, N), 0.01)
        idx = np.flatnonzero(r["labels"] != None)  # noqa: E711
        with open(os.path.join(a.out, fname), "w") as f:
            f.write("time_s,rate_dph,t1_c,t2_c,tcase_c,chamber_c,azimuth_deg,elevation_deg,roll_deg,step\n")
            for k in idx:
                o = r["orients"][r["ori"][k]]
                f.write("%.3f,%.6f,%.4f,%.4f,%.4f,%.3f,%.4f,%.4f,%.4f,%s\n" % (
                    r["tm"][k], rate[k], meas["t1"][k], meas["t2"][k], meas["tk"][k], ch[k], o[0], o[1], o[2],
                    r["labels"][k]))
    with open(os.path.join(a.out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1, default=float)


if __name__ == "__main__":
    main()
