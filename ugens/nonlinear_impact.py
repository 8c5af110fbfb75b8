"""HuntCrossleyImpact: an inertial hammer striking a modal resonator through a nonlinear contact.

The SDT ``impact~`` model (Avanzini & Rocchesso, "Modeling collision sounds: non-linear
contact force", DAFx 2001; SDT ``SDTImpact_MarhefkaOrin``): the Hunt & Crossley (1975)
contact force in Marhefka & Orin's form (IEEE SMC-A 29(6), 1999),

    f = k x^alpha (1 + lambda v)  for x > 0, clamped at 0 (no pulling), 0 otherwise,

x = hammer position minus resonator contact displacement (compression), v = dx/dt. The hammer
(mass m) obeys m x_h'' = -f; each mode (gains a_k at the contact = the driving-point
displacement impulse response, x_c = sum_k q_k) obeys
q_k'' + 2 d_k q_k' + (w_k^2 + d_k^2) q_k = a_k w_k f, w_k = 2 pi f_k.

Discretisation (chosen so that energy provably never increases):

* The force is held constant over each sample (zero-order hold) and the hammer and every
  mode are advanced *exactly* over the sample (the step-invariant discretisation of the
  continuous system: a 2x2 transition matrix and a force vector per mode, vectorised
  across modes). Position and velocity are exact continuous states at the sample instants,
  so the linear part's energy changes exactly by -f (x_{n+1} - x_n) minus its damping loss.
* The force over the sample is the discrete gradient of the contact potential
  V(x) = k x^(alpha+1) / (alpha+1) between the compressions at both ends of the sample,
  times the dissipation factor with the secant velocity (Chatziioannou & van Walstijn,
  "Energy conserving schemes for the simulation of musical instrument contact dynamics",
  J. Sound Vib. 339, 2015):

      f_n = (V(x_{n+1}) - V(x_n)) / (x_{n+1} - x_n) * max(0, 1 + lambda (x_{n+1} - x_n) / T),

  which tends to k x^alpha (1 + lambda v) as T -> 0 (second-order accurate). With
  E = m v_h^2 / 2 + sum_k E_k + V(x) this gives E_{n+1} - E_n = -(modal damping loss)
  - lambda DG (x_{n+1} - x_n)^2 / T <= 0: the pair never gains energy.
* x_{n+1} is affine in f_n (x_{n+1} = x_free - K f_n), so f_n solves one scalar equation,
  monotone in f_n with a unique root in [0, f(x_free)]: bracketed Newton iterations (a few
  per sample in contact, none out of contact). As in SDT, the step's energy is checked
  (a scalar quadratic in f plus V, from sums gathered in the modal pass) and the force is
  bisected towards the energy minimum if a step would raise E (a safeguard against
  rounding; counted in ``stats[6]``; it does not trigger in the tests).

Relation to ModalBank: ModalBank is the same modal system driven by the force as impulses
f[n]/fs at the sample instants (impulse invariance); here the force is held over the
sample. For the same force sequence the two outputs differ by the hold: per mode, the
step-invariant response equals the impulse-invariant one filtered by
(1 - e^{-sT}) / (sT) at s = -d + i w, i.e. about half a sample later and -(w T)^2 / 24 in
level (sinc), e.g. 0.16 dB at 5 kHz at 48 kHz.

Mode energy: with modal mass M_k = 1 / (a_k w_k), E_k = M_k (q'^2 + (w_k^2 + d_k^2) q^2) / 2.
The gains at the contact are the model's driving-point gains (ModalModel.driving_at, >= 0:
a driving-point receptance; negative gains would be negative masses); modes with zero gain
are uncoupled. Output ``contact``: the contact displacement x_c (m) at the end of each
sample, as ModalBank outputs sum_k q_k. Main output: the displacement heard at the model's
pickup, the same modes under the same force with the model's (signed) gains
(:mod:`ugens.heard`, the force held over each sample); it is x_c when the model has no
separate driving-point gains.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba as nb
import numpy as np

from jassy.jit import drop_stale_cache, specialise
from jassy.params import ParamSpec
from jassy.registry import register
from jassy.ugen import UGen
from ugens import cells, heard
from ugens.cells import is_flush_frame, silent, slot, state_step, store
from ugens.heard import STATE_P, STATE_Q, heard_run
from ugens.kernels import FASTMATH
from ugens.modal import HEARD_LEVEL, ModelParams

drop_stale_cache(__file__, [cells, heard])  # its cache holds copies of their kernels


class HammerState(NamedTuple):
    """The hammer at the current instant, stored in this order in the float64 array ``hammer``."""

    xh: float  #: hammer position x_h (m)
    vh: float  #: hammer velocity v_h (m/s)
    xn: float  #: compression x_n (m)
    fp: float  #: force of the last sample, not yet applied to the stored mode states (N)
    en: float  #: energy E_n of hammer, modes and contact (J)
    active: float  #: 1 while the hammer can still touch, 0 once retired
    vn: float  #: contact potential V(x_n) (J)
    fpp: float  #: force of the sample before (N)
    sp: float  #: sum of the mode velocities (contact point velocity) after the last step (m/s)


@nb.njit(inline="always", cache=True)
def hammer_state(hammer):
    """The HammerState record held in ``hammer``."""
    h = hammer
    return HammerState(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8])


#: Where HammerState.active sits in the ``hammer`` array (the per-block silence test).
_ACTIVE = slot(HammerState, "active")


class StrikeStats(NamedTuple):
    """Measurements of the last strike, stored in this order in the float64 array ``stats``."""

    start: float  #: start of the first contact (fractional frame)
    end: float  #: end of the first contact (fractional frame; 0 until known)
    vin: float  #: approach speed (m/s)
    vout: float  #: compression velocity after the first contact (m/s; negative: separating)
    peak: float  #: peak force (N)
    contacts: float  #: contacts ended
    corrections: float  #: samples whose force the energy safeguard reduced
    touching: float  #: 1 while in contact
    measured: float  #: 1 once the first contact is over


@nb.njit(inline="always", cache=True)
def strike_stats(stats):
    """The StrikeStats record held in ``stats``."""
    s = stats
    return StrikeStats(s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8])


class ContactData(NamedTuple):
    """The arrays the closed loop updates."""

    state: np.ndarray  #: (2, K) mode positions q and velocities q' without the pending force
    hammer: np.ndarray  #: a HammerState
    stats: np.ndarray  #: a StrikeStats
    meta: np.ndarray  #: int64 [modes to compute (0 once all are silent and the hammer retired)]


#: The slot of ContactData.meta: the modes to compute.
COMPUTED_MODES = 0


class StepSize(NamedTuple):
    """A step size's coefficients: a (10, K) ModeSteps array and a HammerParams array."""

    coef: np.ndarray
    prm: np.ndarray


class StepSums(NamedTuple):
    """What a step's energy needs besides the force f (from the modal pass)."""

    vh_free: float  #: hammer velocity without the force (m/s)
    s0: float  #: modal energy without the force's share (J)
    s1: float  #: modal energy per force (J/N)
    s2: float  #: modal energy per force^2 (J/N^2)
    x_free: float  #: compression without the force (m)


class ModeSteps(NamedTuple):
    """Rows of the (10, K) coefficient array of :func:`design`: per mode, its step over T."""

    phi11: np.ndarray  #: transition matrix [[phi11, phi12], [phi21, phi22]] of (q, q')
    phi12: np.ndarray
    phi21: np.ndarray
    phi22: np.ndarray
    g_q: np.ndarray  #: force response of the position (m/N)
    g_p: np.ndarray  #: force response of the velocity (m/(N s))
    w_q: np.ndarray  #: energy weight M (w^2 + d^2) / 2 of q^2
    w_p: np.ndarray  #: energy weight M / 2 of q'^2
    decay: np.ndarray  #: d (1/s)
    inv_w: np.ndarray  #: 1 / w (s)


@nb.njit(inline="always", cache=True)
def mode_steps(coef):
    """The ModeSteps record of the rows of ``coef``."""
    return ModeSteps(coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6], coef[7], coef[8], coef[9])


#: Sub-steps per sample while the hammer touches or may touch within the sample.
SUBSTEPS = 8
#: Default approach speed of ``strike`` (m/s): the default 10 g hammer then carries 1e-3 N s,
#: the reference impulse of the level convention (jassy.levels), and delivers up to twice that
#: as it bounces off, so with ``level = "calibrated"`` a default strike on a model whose gains
#: are driving-point receptances (m per N s) peaks near the default ImpactForce tap's level.
#: 1 m/s (a 10 g object dropped 5 cm) would be 20 dB louder: above 0 dBFS on most models.
DEFAULT_STRIKE_SPEED = 0.1


@nb.njit(fastmath=FASTMATH, cache=True)
def power(x, alpha):
    """x^alpha for x > 0, with the common exponents 1.5, 1 and 2 without pow()."""
    if alpha == 1.5:
        return x * math.sqrt(x)
    if alpha == 1.0:
        return x
    if alpha == 2.0:
        return x * x
    return x**alpha


@nb.njit(fastmath=FASTMATH, cache=True)
def potential(x, k, alpha):
    """V(x) = k x^(alpha+1) / (alpha+1) for x > 0, else 0 (J)."""
    if x <= 0.0:
        return 0.0
    return k * x * power(x, alpha) / (alpha + 1.0)


@nb.njit(fastmath=FASTMATH, cache=True)
def discrete_gradient(x0, v0, y, k, alpha):
    """(DG, dDG/dy, V(y)): DG = (V(y) - V(x0)) / (y - x0), or V' at the midpoint for y ~ x0.

    v0 = V(x0) (known from the previous sample); one power per call. For
    |y - x0| < 1e-4 max(|x0|, |y|) (both > 0) the secant would cancel: use
    DG = V'(m) + V'''(m) h^2 / 24 (m midpoint, h = y - x0), exact to O(h^4).
    """
    if y <= 0.0:
        if x0 <= 0.0:
            return 0.0, 0.0, 0.0
        h = y - x0
        dg = -v0 / h
        return dg, -dg / h, 0.0
    ya = power(y, alpha)
    vy = k * y * ya / (alpha + 1.0)
    h = y - x0
    if abs(h) > 1e-4 * max(abs(x0), y):
        dg = (vy - v0) / h
        return dg, (k * ya - dg) / h, vy
    m = 0.5 * (x0 + y)
    ma = power(m, alpha)
    c3 = k * alpha * (alpha - 1.0) * ma / (m * m)
    dg = k * ma + c3 * h * h / 24.0
    ddg = 0.5 * k * alpha * ma / m + c3 * h / 12.0
    return dg, ddg, vy


@nb.njit(fastmath=FASTMATH, cache=True)
def contact_force(x0, v0, y, k, alpha, lam, inv_t):
    """(P(y), dP/dy, V(y)): P = DG(x0, y) max(0, 1 + lam (y - x0) / T)."""
    dg, ddg, vy = discrete_gradient(x0, v0, y, k, alpha)
    fac = 1.0 + lam * (y - x0) * inv_t
    if fac <= 0.0 or dg <= 0.0:
        return 0.0, 0.0, vy
    return dg * fac, ddg * fac + dg * lam * inv_t, vy


@nb.njit(fastmath=FASTMATH, cache=True)
def solve_force(x0, v0, x_free, kk, k, alpha, lam, inv_t, guess):
    """The force f >= 0 with f = P(x_free - kk f) (unique: f - P(x_free - kk f) increases).

    Bracketed Newton iterations: the root lies in [0, P(x_free)]. From ``guess`` (the
    extrapolated previous force) if positive, the upper end P(x_free) is only evaluated
    when a Newton step leaves the bracket; otherwise from one Newton step from 0.
    """
    p_hi = -1.0  # P(x_free), not yet known
    hi = 1e300  # no upper end yet
    if guess > 0.0:
        f = guess
    else:
        p_hi, dp, _ = contact_force(x0, v0, x_free, k, alpha, lam, inv_t)
        if p_hi <= 0.0:
            return 0.0
        hi = p_hi
        f = p_hi / (1.0 + kk * dp)  # one Newton step from f = 0
    lo = 0.0
    for _ in range(80):
        p, dp, _ = contact_force(x0, v0, x_free - kk * f, k, alpha, lam, inv_t)
        r = f - p
        if r < 0.0:
            lo = f
        else:
            hi = f
        f_new = f - r / (1.0 + kk * dp)
        if abs(f_new - f) <= 1e-14 * f:
            return max(f_new, 0.0)  # converged (whatever the bracket's rounding says)
        if not (lo < f_new < hi):
            if p_hi < 0.0:
                p_hi, _, _ = contact_force(x0, v0, x_free, k, alpha, lam, inv_t)
                if p_hi <= 0.0:
                    return 0.0
                hi = min(hi, p_hi)
            if not (lo < f_new < hi):
                f_new = 0.5 * (lo + hi)
        f = f_new
        if hi - lo <= 1e-14 * hi:  # (never true while hi is still infinite)
            break
    return f


@nb.njit(fastmath=FASTMATH, cache=True)
def step_energy(f, sums, p):
    """(E, V(x1)) after a step with force f: hammer kinetic + modal quadratic + V(x1).
    sums: the step's StepSums, p: its HammerParams."""
    mass = p.mass
    v = sums.vh_free - f * p.step / mass
    vx = potential(sums.x_free - p.compliance * f, p.stiffness, p.alpha)
    return 0.5 * mass * v * v + sums.s0 + f * sums.s1 + f * f * sums.s2 + vx, vx


@nb.njit(fastmath=FASTMATH, cache=True)
def energy_safeguard(f, e_prev, sums, p):
    """The force nearest f whose step does not raise the energy above e_prev (bisection,
    as SDT), or the energy minimiser if none does. E(f) is convex in f."""
    args = (sums, p)
    hi = max(f, 1e-300)
    for _ in range(200):  # grow hi until E increases there (beyond the minimiser)
        if step_energy(hi * (1.0 + 1e-9), *args)[0] >= step_energy(hi, *args)[0]:
            break
        hi *= 2.0
    lo = 0.0
    for _ in range(100):  # bisection on the sign of the slope
        mid = 0.5 * (lo + hi)
        if step_energy(mid * (1.0 + 1e-9) + 1e-300, *args)[0] < step_energy(mid, *args)[0]:
            lo = mid
        else:
            hi = mid
    good = 0.5 * (lo + hi)
    if step_energy(good, *args)[0] > e_prev:
        return good
    bad = f  # bisect towards f on the sublevel set {E <= e_prev}
    for _ in range(60):
        mid = 0.5 * (good + bad)
        if step_energy(mid, *args)[0] <= e_prev:
            good = mid
        else:
            bad = mid
    return good


class HammerParams(NamedTuple):
    """The contact's scalar parameters for one step size T, stored in this order in the float64
    arrays ``prm`` (a sample) and ``prm_sub`` (a sub-step)."""

    mass: float  #: hammer mass m (kg)
    stiffness: float  #: contact stiffness k (N/m^alpha)
    alpha: float  #: contact exponent
    dissipation: float  #: Hunt-Crossley lambda (s/m)
    step: float  #: T (s)
    compliance: float  #: K = T^2/(2 m) + G: x_{n+1} = x_free - K f_n (m/N)
    gain_sum: float  #: G = sum_k g1_k, the modes' contact displacement per force (m/N)
    energy_gain: float  #: S2 = sum_k (wq g1^2 + wp g2^2), the modes' energy per force^2 (J/N^2)
    floor: float  #: mode amplitude below which a silent mode is zeroed (m)


@nb.njit(inline="always", cache=True)
def hammer_params(prm):
    """The HammerParams record held in ``prm``."""
    return HammerParams(prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8])


@nb.njit(inline="always", cache=True)
def modal_pass(qs, ps, steps, kmodes, fp):
    """The first ``kmodes`` modes (positions qs, velocities ps) one step on (``steps``: a
    ModeSteps), the pending force fp applied first. Returns the sums the step's solve and
    energy need: (contact displacement sum q (m), contact velocity sum q' (m/s), modal energy
    S0 (J), modal energy per force S1 (J/N))."""
    sq = 0.0
    sp = 0.0
    s0 = 0.0
    s1 = 0.0
    for j in range(kmodes):
        q = qs[j] + steps.g_q[j] * fp
        pj = ps[j] + steps.g_p[j] * fp
        qn, pn = state_step(steps.phi11[j], steps.phi12[j], steps.phi21[j], steps.phi22[j], q, pj)
        qs[j] = qn
        ps[j] = pn
        sq += qn
        sp += pn
        s0 += steps.w_q[j] * qn * qn + steps.w_p[j] * pn * pn
        s1 += steps.w_q[j] * steps.g_q[j] * qn + steps.w_p[j] * steps.g_p[j] * pn
    return sq, sp, s0, 2.0 * s1


@nb.njit(inline="always", cache=True)
def modes_reach(qs, ps, steps, kmodes):
    """The largest contact displacement (m) the free, damped modes can still reach: mode j is
    e^{-dt}(A cos wt + B sin wt), |.| <= sqrt(A^2 + B^2), A = q, B = (q' + d q) / w."""
    reach = 0.0
    for j in range(kmodes):
        b = (ps[j] + steps.decay[j] * qs[j]) * steps.inv_w[j]
        reach += math.sqrt(qs[j] * qs[j] + b * b)
    return reach


@nb.njit(inline="always", cache=True)
def flush_silent_modes(qs, ps, inv_w, kmodes, floor):
    """Zero the modes below ``floor`` (position and velocity / w, both displacements in m);
    return the count of modes up to the last audible one."""
    last = 0
    for j in range(kmodes):
        if silent(qs[j], ps[j] * inv_w[j], floor):
            qs[j] = 0.0
            ps[j] = 0.0
        else:
            last = j + 1
    return last


@nb.njit(fastmath=FASTMATH, cache=True)
def hc_run(out, force_out, energy_out, start, n, step, d):
    """Frames start..start+n-1: per sample, one pass over the modes, then the scalar solve.

    step: the StepSize (coefficients, HammerParams); d: the ContactData, whose mode states
    are kept *without* the last force (the hammer's ``fp``, applied at the start of the
    next pass).
    """
    p = hammer_params(step.prm)
    mass, k, alpha, lam, tt = p.mass, p.stiffness, p.alpha, p.dissipation, p.step
    kk, gg, floor = p.compliance, p.gain_sum, p.floor
    inv_t = 1.0 / tt
    steps = mode_steps(step.coef)
    qs = d.state[STATE_Q]
    ps = d.state[STATE_P]
    meta = d.meta
    h = hammer_state(d.hammer)
    xh, vh, xn, fp, en, vn, fpp, sp = h.xh, h.vh, h.xn, h.fp, h.en, h.vn, h.fpp, h.sp
    active = h.active != 0.0
    st = strike_stats(d.stats)
    end, vout, peak, contacts = st.end, st.vout, st.peak, st.contacts
    corrections, touching, measured = st.corrections, st.touching, st.measured
    measuring = False  # whether a stat changed
    for i in range(n):
        kmodes = meta[COMPUTED_MODES]
        sq, sp, s0, s1 = modal_pass(qs, ps, steps, kmodes, fp)
        xh_free = xh + tt * vh
        x0 = xn
        x_free = xh_free - sq
        v0 = vn
        f = 0.0
        if active and (x0 > 0.0 or x_free > 0.0):
            # guess: linear extrapolation of the last two forces
            f = solve_force(x0, v0, x_free, kk, k, alpha, lam, inv_t, 2.0 * fp - fpp if fpp > 0.0 else fp)
        sums = StepSums(vh, s0, s1, p.energy_gain, x_free)
        e1, v1 = step_energy(f, sums, p)
        if f > 0.0 and e1 > en * (1.0 + 1e-13):
            f = energy_safeguard(f, en, sums, p)
            e1, v1 = step_energy(f, sums, p)
            corrections += 1.0
        x1 = x_free - kk * f
        frame = start + i
        if f > 0.0:
            measuring = True
            touching = 1.0
            if f > peak:
                peak = f
        if x0 > 0.0 and x1 <= 0.0 and measured == 0.0:
            measuring = True
            end = frame + x0 / (x0 - x1)  # where the compression crosses 0
        if f == 0.0 and touching != 0.0:
            measuring = True
            touching = 0.0
            contacts += 1.0
            if measured == 0.0:
                measured = 1.0
                vout = vh - sp  # compression velocity after a force-free sample
        xh = xh_free - f * tt * tt / (2.0 * mass)
        vh = vh - f * tt / mass
        xn = x1
        fpp = fp
        fp = f
        en = e1
        vn = v1
        out[i] = sq + gg * f
        force_out[i] = f
        energy_out[i] = e1
        if is_flush_frame(frame + 1) and f == 0.0:  # the next frame is a flush frame
            if active and vh <= 0.0 and xh + modes_reach(qs, ps, steps, kmodes) < 0.0:
                active = False  # moving away, and no free, damped mode can reach it again
            if not active:
                meta[COMPUTED_MODES] = flush_silent_modes(qs, ps, steps.inv_w, kmodes, floor)
    store(d.hammer, HammerState(xh, vh, xn, fp, en, 1.0 if active else 0.0, vn, fpp, sp))
    if measuring:  # (most calls are one sample between contacts: nothing to write back)
        store(
            d.stats, StrikeStats(st.start, end, st.vin, vout, peak, contacts, corrections, touching, measured)
        )


@nb.njit(fastmath=FASTMATH, cache=True)
def commit_force(state, hammer, coef):
    """Apply the pending force (the HammerState's ``fp``) to the mode states with the force
    response of the step (coef) that produced it; the force history is cleared."""
    h = hammer_state(hammer)
    if h.fp != 0.0:
        steps = mode_steps(coef)
        for j in range(state.shape[1]):
            state[STATE_Q, j] += steps.g_q[j] * h.fp
            state[STATE_P, j] += steps.g_p[j] * h.fp
    store(hammer, HammerState(h.xh, h.vh, h.xn, 0.0, h.en, h.active, h.vn, 0.0, h.sp))


#: Rows of hc_run_substeps' scratch (3, M): a sample's sub-step outputs, forces, energies.
SUB_OUT, SUB_FORCE, SUB_ENERGY = 0, 1, 2


@nb.njit(fastmath=FASTMATH, cache=True)
def hc_run_substeps(out, force_out, energy_out, start, n, full, sub, d, scratch):
    """hc_run over frames start..start+n-1 with steps of ``full`` (a StepSize of one sample),
    but each sample in which the hammer touches or may touch (compression > 0, or > 0
    within two samples at the current compression velocity) is integrated in
    scratch.shape[1] sub-steps of ``sub`` (the step T / M). The force is then resolved at M
    points per sample: the exact modal steps hold it over T / M, so the hold's low-pass
    (sinc) and the discrete gradient's error move M times higher. The force output of such
    a sample is its mean (impulse / T). Between samples the pending force is always one of
    a full step."""
    m_sub = scratch.shape[1]
    tt = hammer_params(full.prm).step
    for i in range(n):
        frame = start + i
        h = hammer_state(d.hammer)
        if h.active == 0.0:  # retired: no contact in the rest of the block
            hc_run(out[i:], force_out[i:], energy_out[i:], frame, n - i, full, d)
            return
        near = h.xn + 2.0 * tt * (h.vh - h.sp) > 0.0
        if h.xn > 0.0 or near:
            commit_force(d.state, d.hammer, full.coef)
            end = strike_stats(d.stats).end
            hc_run(scratch[SUB_OUT], scratch[SUB_FORCE], scratch[SUB_ENERGY], 0, m_sub, sub, d)
            s = strike_stats(d.stats)
            if s.end != end:  # the contact ended in this sample: its sub-step, in frames
                ended = frame + s.end / m_sub
                store(d.stats, StrikeStats(s.start, ended, s.vin, s.vout, s.peak, s.contacts, s.corrections,
                                           s.touching, s.measured))  # fmt: skip
            commit_force(d.state, d.hammer, sub.coef)
            out[i] = scratch[SUB_OUT, m_sub - 1]
            mean = 0.0
            for m in range(m_sub):
                mean += scratch[SUB_FORCE, m]
            force_out[i] = mean / m_sub  # the sample's impulse / T
            energy_out[i] = scratch[SUB_ENERGY, m_sub - 1]
        else:
            hc_run(out[i:], force_out[i:], energy_out[i:], frame, 1, full, d)


def design(frequencies, decays, gains, sample_rate):
    """Step-invariant (exact zero-order-hold) coefficients per mode: a ModeSteps as a (10, K) array.

    Transition over T = 1/fs of q'' + 2 d q' + (w^2 + d^2) q = b f (b = a w), with
    E = e^{-dT}, c = cos wT, s = sin wT:
    phi = E [[c + d s / w, s / w], [-(w^2 + d^2) s / w, c - d s / w]];
    force response g1 = b (1 - E (c + d s / w)) / (w^2 + d^2), g2 = a E s (the mode's step
    response and impulse response a e^{-dt} sin(wt) at t = T). 1 - E (c + d s / w) is
    evaluated as -expm1(-dT) + 2 E sin^2(wT/2) - E d s / w to keep precision for low wT.
    """
    T = 1.0 / sample_rate
    w = 2.0 * np.pi * np.asarray(frequencies, dtype=np.float64)
    d = np.asarray(decays, dtype=np.float64)
    a = np.asarray(gains, dtype=np.float64)
    om2 = w * w + d * d
    E = np.exp(-d * T)
    c = np.cos(w * T)
    s = np.sin(w * T)
    phi11 = E * (c + d * s / w)
    phi12 = E * s / w
    phi21 = -E * om2 * s / w
    phi22 = E * (c - d * s / w)
    one_minus = -np.expm1(-d * T) + 2.0 * E * np.sin(0.5 * w * T) ** 2 - E * d * s / w
    coupled = a > 0
    mass = np.where(coupled, 1.0 / np.where(coupled, a * w, 1.0), 0.0)  # modal mass M = 1/(a w)
    steps = ModeSteps(
        phi11=phi11,
        phi12=phi12,
        phi21=phi21,
        phi22=phi22,
        g_q=a * w * one_minus / om2,
        g_p=a * E * s,
        w_q=0.5 * mass * om2,
        w_p=0.5 * mass,
        decay=d,
        inv_w=1.0 / w,
    )
    return np.array(steps, dtype=np.float64)


@register
class HuntCrossleyImpact(ModelParams, UGen):
    """Hammer (mass m) striking a modal resonator: Hunt-Crossley force k x^alpha (1 + lambda v).

    SDT impact~ (Avanzini & Rocchesso, DAFx 2001), Marhefka & Orin (1999) form; energy-
    consistent discretisation (exact modal steps under a held force, discrete-gradient
    force: Chatziioannou & van Walstijn, JSV 2015). Main output: displacement at the
    model's pickup (m, signed gains; times the model's reference gain with ``level =
    "calibrated"``, the scale of a calibrated ModalBank); ``contact``: contact displacement (m, driving-point
    gains); ``force``: contact force (N); ``energy``: E of hammer + modes + contact (J).
    """

    type_name = "HuntCrossleyImpact"
    outputs = ("force", "energy", "contact")
    driving_point = True
    param_specs = {
        "model": ParamSpec("model", required=True, fixed=True, doc="the resonator's ModalModel"),
        "location": ParamSpec("location", 0, doc="contact location: vertex, point name or barycentric"),
        "mass": ParamSpec("float", 0.01, low=0.0, low_open=True, high=1e6, unit="kg", doc="hammer mass m"),
        "stiffness": ParamSpec(
            "float",
            1e7,
            low=0.0,
            low_open=True,
            high=1e16,
            unit="N/m^alpha",
            doc="contact stiffness k (a sphere: 4/3 E* sqrt(R) with alpha = 1.5)",
        ),
        "alpha": ParamSpec(
            "float", 1.5, low=1.0, high=4.0, doc="contact exponent (1.5: Hertz sphere on a plane)"
        ),
        "dissipation": ParamSpec(
            "float", 0.5, low=0.0, high=1e4, unit="s/m", doc="Hunt-Crossley dissipation lambda"
        ),
        "floor": ParamSpec(
            "float",
            1e-13,
            low=0.0,
            high=1e-3,
            fixed=True,
            unit="m",
            doc="mode amplitude below which a silent mode is zeroed (only once the hammer has left)",
        ),
        "level": HEARD_LEVEL,
    }
    actions = {
        "strike": {
            "speed": ParamSpec(
                "float",
                DEFAULT_STRIKE_SPEED,
                low=0.0,
                low_open=True,
                high=1e4,
                unit="m/s",
                doc="approach speed of the hammer at contact (default: the default hammer's momentum is "
                "the reference impulse 1e-3 N s, so a calibrated strike sounds like ImpactForce's default)",
            ),
            "location": ParamSpec("location", None, doc="contact location (default: the current one)"),
        }
    }

    # --------------------------------------------------------------- lifecycle
    def _prepare(self) -> None:
        self.validate_model()
        model = self.model
        self.check_param("location", self.values["location"], f"nodes.{self.name}.location")
        self.order = np.argsort(model.decays, kind="stable")  # slowest first: silent modes last
        k = model.n_modes
        self.coef = np.zeros((len(ModeSteps._fields), k))
        self.coef_sub = np.zeros((len(ModeSteps._fields), k))
        self.state = np.zeros((2, k))
        self.hammer = np.zeros(len(HammerState._fields))
        self.stats = np.zeros(len(StrikeStats._fields))
        self.prm = np.zeros(len(HammerParams._fields))
        self.prm_sub = np.zeros(len(HammerParams._fields))
        self.meta = np.zeros(1, dtype=np.int64)
        self._scratch = np.zeros((3, SUBSTEPS))
        self.signed = model.driving is not None  # heard through the signed gains
        self.heard_coef = np.zeros((6, k))
        self.heard_state = np.zeros((2, k))
        self._level_gain = self.level_gain()
        self._design()
        self._steps = StepSize(self.coef, self.prm), StepSize(self.coef_sub, self.prm_sub)
        self._data = ContactData(self.state, self.hammer, self.stats, self.meta)
        x = self.out
        self._run = specialise(hc_run_substeps, x, x, x, 0, 0, *self._steps, self._data, self._scratch)

    def _design(self) -> None:
        """Coefficients and scalar parameters from the current values (state untouched), for
        a sample and for a sub-step."""
        v, model, o = self.values, self.model, self.order
        gains = model.driving_at(v["location"])[o]
        if self.signed:
            signed = model.gains_at(v["location"])[o] * self._level_gain
            self.heard_coef[:] = design(model.frequencies[o], model.decays[o], signed, self.sample_rate)[:6]
        for coef, prm, rate in ((self.coef, self.prm, self.sample_rate),
                                (self.coef_sub, self.prm_sub, self.sample_rate * SUBSTEPS)):  # fmt: skip
            coef[:] = design(model.frequencies[o], model.decays[o], gains, rate)
            T = 1.0 / rate
            m = v["mass"]
            steps = ModeSteps(*coef)
            g1, g2, wq, wp = steps.g_q, steps.g_p, steps.w_q, steps.w_p
            G = float(np.sum(g1))
            S2 = float(np.sum(wq * g1 * g1 + wp * g2 * g2))
            prm[:] = HammerParams(
                mass=m,
                stiffness=v["stiffness"],
                alpha=v["alpha"],
                dissipation=v["dissipation"],
                step=T,
                compliance=T * T / (2 * m) + G,
                gain_sum=G,
                energy_gain=S2,
                floor=v["floor"],
            )

    @property
    def params(self) -> HammerParams:
        """The contact's parameters for a full sample step."""
        return HammerParams(*self.prm)

    def _reset(self) -> None:
        self.heard_state[:] = 0.0
        self.state[:] = 0.0
        self.hammer[:] = 0.0
        self.stats[:] = 0.0
        self.meta[COMPUTED_MODES] = 0

    def _commit_force(self) -> None:
        """Apply the last sample's force to the stored mode states (before coefficients change)."""
        commit_force(self.state, self.hammer, self.coef)

    def _param_changed(self, key: str, value: Any, jump: bool) -> None:
        self._commit_force()
        self._design()
        h = HammerState(*self.hammer)
        self.hammer[:] = h._replace(vn=potential(h.xn, self.params.stiffness, self.params.alpha))
        self._set_energy()

    # ------------------------------------------------------------------ events
    def act(self, action: str, args: dict[str, Any], sample_time: float) -> None:
        """``strike``: put the hammer at contact at ``sample_time`` with approach ``speed``."""
        if action != "strike":
            return super().act(action, args, sample_time)
        if args.get("location") is not None:
            self.set_param("location", args["location"], jump=True)
        self._commit_force()
        v0 = args["speed"]
        frame = math.ceil(sample_time - 1e-6)  # the frame the scheduler applies the event at
        lead = max(frame - sample_time, 0.0) / self.sample_rate  # s of contact before that frame
        xc = float(np.sum(self.state[STATE_Q]))
        vc = float(np.sum(self.state[STATE_P]))
        xn = v0 * lead
        self.hammer[:] = HammerState(*self.hammer)._replace(
            xh=xc + v0 * lead,
            vh=vc + v0,
            sp=vc,
            xn=xn,
            vn=potential(xn, self.params.stiffness, self.params.alpha),
            active=1.0,
        )
        self.stats[:] = StrikeStats(*np.zeros(len(StrikeStats._fields)))._replace(start=sample_time, vin=v0)
        self.meta[COMPUTED_MODES] = self.model.n_modes
        self._set_energy()

    def _set_energy(self) -> None:
        """Store the energy of the current state as the hammer's E_n."""
        self.hammer[:] = HammerState(*self.hammer)._replace(en=self.energy())

    # ------------------------------------------------------------- measurement
    def energy(self) -> float:
        """E (J) of the current state: m v_h^2/2 + sum_k M_k (q'^2 + (w^2 + d^2) q^2)/2 + V(x),
        computed here in Python from the state arrays (independent of the kernel's sums)."""
        h = HammerState(*self.hammer)
        steps = ModeSteps(*self.coef)
        q = self.state[STATE_Q] + steps.g_q * h.fp
        p = self.state[STATE_P] + steps.g_p * h.fp
        modal = float(np.sum(steps.w_q * q * q + steps.w_p * p * p))
        x = h.xh - float(np.sum(q))
        m, k, alpha = self.params.mass, self.params.stiffness, self.params.alpha
        return 0.5 * m * h.vh**2 + modal + float(potential(x, k, alpha))

    @property
    def rebound_velocity(self) -> float | None:
        """Compression velocity (m/s) just after the first contact of the last strike:
        negative when the hammer separates (rebound speed = -this); None while in contact."""
        s = StrikeStats(*self.stats)
        return float(s.vout) if s.measured else None

    @property
    def rebound_speed(self) -> float | None:
        """Speed (m/s) at which the hammer leaves the surface after the first contact
        (-rebound_velocity); None while in contact."""
        v = self.rebound_velocity
        return None if v is None else -v

    @property
    def contact_time(self) -> float | None:
        """Duration (s) of the first contact of the last strike (compression > 0), or None."""
        s = StrikeStats(*self.stats)
        if not s.measured or s.end == 0.0:
            return None
        return float(s.end - s.start) / self.sample_rate

    @property
    def corrections(self) -> int:
        """Samples whose force the energy safeguard had to reduce since the last strike."""
        return int(StrikeStats(*self.stats).corrections)

    # -------------------------------------------------------------- processing
    def process(self, start: int, n: int) -> None:
        self._contact(start, n)
        if not self.signed:
            np.multiply(self.extra["contact"][:n], self._level_gain, out=self.out[:n])
        elif self._silent():  # the loop's modes fell silent
            self.out[:n] = 0.0
            self.heard_state[:] = 0.0
        else:
            heard_run(self.extra["force"], self.out, n, self.heard_coef, self.heard_state)

    def _contact(self, start: int, n: int) -> None:
        """The closed loop: contact displacement, force and energy."""
        force, energy = self.extra["force"], self.extra["energy"]
        if self._silent():  # no mode to compute and no hammer that can touch: free flight
            self.extra["contact"][:n] = 0.0
            force[:n] = 0.0
            h = HammerState(*self.hammer)
            m, v = self.params.mass, h.vh
            self.hammer[:] = h._replace(xh=h.xh + v * n / self.sample_rate)
            energy[:n] = 0.5 * m * v * v
            return
        self._run(self.extra["contact"], force, energy, start, n, *self._steps, self._data, self._scratch)

    def _silent(self) -> bool:
        """No mode left to compute and the hammer retired (read once per block: one field)."""
        return self.meta[COMPUTED_MODES] == 0 and self.hammer[_ACTIVE] == 0.0

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {
            "state": self.state,
            "hammer": self.hammer,
            "stats": self.stats,
            "meta": self.meta,
            "heard_state": self.heard_state,
        }
