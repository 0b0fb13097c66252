"""Compiled (numba) variable-step integrator of the full vehicle model: Dormand-Prince 5(4).

The same equations as the fixed-step RK4 kernel: every stage calls ``_kernel.deriv``
(states, strut states, inputs, parameters and road exactly as there), only the
integration differs.  This is how a multibody code (ADAMS, Simpack) integrates: an
embedded Runge-Kutta pair estimates the local error of every step and a step-size
controller keeps it within a tolerance, so the step grid adapts to the solution.

Method (Hairer, Norsett & Wanner, *Solving ODEs I*, 2nd ed., section II.4-II.6, and
their DOPRI5 code):

* Dormand & Prince (1980) 5(4) pair, 7 stages with the last one at the new point
  (FSAL: 6 derivative calls per step); the 5th-order solution is propagated;
* error norm ``sqrt(mean((err_i / sc_i)^2))`` with ``sc_i = atol + rtol max(|y0_i|, |y1_i|)``
  (HNW II.4, eq. 4.11); a step is accepted when the norm is <= 1;
* PI step-size controller (HNW IV.2 / DOPRI5): ``h_new = h / fac``,
  ``fac = clip(err^(0.2 - 0.75 beta) / errold^beta / safety, 1/fac_max, 1/fac_min)``;
  after a rejection the step may not grow;
* dense output of order 4 (HNW II.6, Dormand-Prince continuous extension, DOPRI5
  ``contd5``) gives the state at every point of the fixed metric grid (``dt``), where
  ``_kernel.deriv`` then evaluates the outputs (seat accelerations, tyre forces...).

Driver and speed controller (the laws of ``_kernel.controller``): with
``continuous`` they are evaluated at every stage, as the control elements of a
multibody model are (Adams/Car's driving machine, a PI speed control written as a
differential equation), and the PI integral is one more state; nothing then forces the
steps onto a grid.  With ``continuous`` False they keep the fixed-step kernel's 100 Hz
zero-order hold and the integrator stops exactly at every sample (an input
discontinuity), as Adams and Simulink do for sampled elements; the proposed step size
and the controller's error memory carry over from one segment to the next (``hstate``).
There is no event location: tyre lift-off, bump-stop contact, the damper table's knots
and the kinks of the linearly interpolated road are found by the error estimate alone,
as in a multibody code without sensors.

Designs are independent (no coupling): a design gives the same bits alone or in any
batch.  Nothing random: every difference between two designs' step grids comes from
their solutions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._kernel import (
    C_SPC,
    C_SPEED_ON,
    C_STEER_ON,
    C_TC,
    N_FULL,
    N_HIST,
    N_WORK,
    controller,
    deriv,
)

# ---- controller settings vector ``ctl`` --------------------------------------------------
T_RTOL, T_ATOL, T_HMIN, T_HMAX, T_SAFETY, T_FACMIN, T_FACMAX, T_BETA = range(8)
N_TOL = 8

# ---- per-design statistics ``stats`` (carried over between calls) -------------------------
(
    S_ACCEPTED,
    S_REJECTED,
    S_CALLS,
    S_HMIN_USED,
    S_HMAX_USED,
    S_ERROLD,
    S_NLOG,
    S_FAILED,
    S_FAIL_T,
) = range(9)
N_STATS = 9

# ---- Dormand-Prince 5(4) tableau (HNW Table II.5.2) -------------------------------------
DP5_A = np.zeros((7, 7))
DP5_A[1, 0] = 1.0 / 5.0
DP5_A[2, 0], DP5_A[2, 1] = 3.0 / 40.0, 9.0 / 40.0
DP5_A[3, 0], DP5_A[3, 1], DP5_A[3, 2] = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
DP5_A[4, 0], DP5_A[4, 1], DP5_A[4, 2], DP5_A[4, 3] = (
    19372.0 / 6561.0,
    -25360.0 / 2187.0,
    64448.0 / 6561.0,
    -212.0 / 729.0,
)
DP5_A[5, 0], DP5_A[5, 1], DP5_A[5, 2], DP5_A[5, 3], DP5_A[5, 4] = (
    9017.0 / 3168.0,
    -355.0 / 33.0,
    46732.0 / 5247.0,
    49.0 / 176.0,
    -5103.0 / 18656.0,
)
# the 5th-order weights b_j (the last row: stage 7 is evaluated at the new point, FSAL)
DP5_A[6, 0], DP5_A[6, 2], DP5_A[6, 3], DP5_A[6, 4], DP5_A[6, 5] = (
    35.0 / 384.0,
    500.0 / 1113.0,
    125.0 / 192.0,
    -2187.0 / 6784.0,
    11.0 / 84.0,
)
#: b_j - b*_j: the error estimate's weights (5th minus 4th order), DOPRI5 e1..e7
DP5_E = np.array(
    [
        71.0 / 57600.0,
        0.0,
        -71.0 / 16695.0,
        71.0 / 1920.0,
        -17253.0 / 339200.0,
        22.0 / 525.0,
        -1.0 / 40.0,
    ]
)
#: dense-output weights of the continuous extension, DOPRI5 d1..d7
DP5_D = np.array(
    [
        -12715105075.0 / 11282082432.0,
        0.0,
        87487479700.0 / 32700410799.0,
        -10690763975.0 / 1880347072.0,
        701980252875.0 / 199316789632.0,
        -1453857185.0 / 822651844.0,
        69997945.0 / 29380423.0,
    ]
)

# ---- Bogacki-Shampine 3(2) tableau (HNW II.4; MATLAB ode23), FSAL, Hermite dense output
BS3_A = np.zeros((4, 4))
BS3_A[1, 0] = 0.5
BS3_A[2, 1] = 0.75
BS3_A[3, 0], BS3_A[3, 1], BS3_A[3, 2] = 2.0 / 9.0, 1.0 / 3.0, 4.0 / 9.0
#: b - b* with the embedded 2nd-order weights b* = (7/24, 1/4, 1/3, 1/8)
BS3_E = np.array([2.0 / 9.0 - 7.0 / 24.0, 1.0 / 12.0, 1.0 / 9.0, -1.0 / 8.0])
BS3_D = np.zeros(0)  # no continuous-extension weights: cubic Hermite

#: pair name -> (A, E, dense weights, stages, order of the error estimate)
PAIRS = {
    'dopri5': (DP5_A, DP5_E, DP5_D, 7, 4),
    'bs32': (BS3_A, BS3_E, BS3_D, 4, 2),
}



@njit(cache=True)
def _emit(full_out, hist_out, bi, jj, hj, full, hist, step0, decim):
    """Store the outputs of grid point ``jj`` (every point; histories every ``decim``)."""
    if full_out.shape[2] > 0:
        for c in range(N_FULL):
            full_out[bi, c, jj] = full[c]
    if hist_out.shape[2] > 0 and (step0 + jj) % decim == 0:
        for c in range(N_HIST):
            hist_out[bi, c, hj] = hist[c]
        hj += 1
    return hj


@njit(cache=True)
def _rhs(y, out, cont, ss, uin, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl, rzr, full, hist, want,
         work, C, ytab, cscr):  # fmt: skip
    """Derivative of the augmented state: ``_kernel.deriv`` plus the PI integral's rate.

    The last component of ``y`` is the speed controller's integral.  With continuous
    controllers (``cont``) the driver and the speed controller (``_kernel.controller``,
    the same laws) set the inputs from ``y`` itself, and the integral's rate is the
    speed error (zero while the force saturates, the same anti-windup); otherwise the
    held inputs are used and the integral stays constant.
    """
    n = out.shape[0] - 1
    if cont:
        cscr[0] = y[n]
        controller(y, uin, cscr, C, ytab)
        out[n] = (cscr[0] - y[n]) / C[C_TC]
    else:
        out[n] = 0.0
    deriv(y, ss, uin, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl, rzr, out, full, hist, want, work)


@njit(cache=True, parallel=True)
def integrate_variable(
    states,
    sstates,
    inputs,
    P,
    Minv,
    pc,
    dk,
    dv,
    ds,
    rx0,
    rdx,
    rzl,
    rzr,
    dt,
    n_steps,
    step0,
    decim,
    full_out,
    hist_out,
    cstates,
    C,
    ytab,
    ctl,
    tab_a,
    tab_e,
    tab_d,
    n_stages,
    err_order,
    continuous,
    hstate,
    stats,
    step_log,
):
    """Advance every design by ``n_steps`` output intervals of ``dt`` (in place).

    Parameters as :func:`_kernel.integrate` (outputs at the grid points ``step0 + k``,
    k = 0..n_steps-1, before the interval), plus

    ctl : (N_TOL,) rtol, atol, h_min, h_max [s], safety, fac_min, fac_max, beta.
    tab_a, tab_e, tab_d, n_stages, err_order : the pair (:data:`PAIRS`).
    continuous : bool
        Driver and speed controller evaluated at every stage (continuous control
        elements, as in a multibody model); False: sampled every ``C[C_SPC]`` grid
        points (zero-order hold) and the integrator stops at every sample.
    hstate : (batch,) proposed next step size [s] (updated).
    stats : (batch, N_STATS) accepted/rejected steps, derivative calls, smallest and
        largest accepted step [s], the controller's last error norm, logged steps,
        failure flag and the failure time [s] (updated).
    step_log : (batch, 2, m) time [s] at the end and size [s] of accepted steps, the
        first m of them (m = 0: no log).
    """
    n_b = states.shape[0]
    n = states.shape[1] + 1  # augmented by the speed controller's integral
    rtol = ctl[T_RTOL]
    atol = ctl[T_ATOL]
    hmin = ctl[T_HMIN]
    hmax = ctl[T_HMAX]
    safe = ctl[T_SAFETY]
    facc1 = 1.0 / ctl[T_FACMIN]
    facc2 = 1.0 / ctl[T_FACMAX]
    beta = ctl[T_BETA]
    expo1 = 1.0 / (err_order + 1.0) - 0.75 * beta
    ns = n_stages
    hermite = tab_d.shape[0] == 0
    log_cap = step_log.shape[2]
    spc = int(C[C_SPC])
    ctrl_on = C[C_STEER_ON] > 0.0 or C[C_SPEED_ON] > 0.0
    cont = continuous and ctrl_on
    sampled = ctrl_on and not cont
    # Run-time booleans and integers for the calls below: numba compiles a called
    # function once more for each literal argument (True, False, 0), and _rhs takes
    # _kernel.deriv along (three more compilations, ~10 s of a first compile).
    outputs = n_steps >= 0  # True
    no_outputs = not outputs
    for bi in prange(n_b):
        kk = np.empty((7, n))
        tmp = np.empty(n)
        s = np.empty(n)
        y0 = np.empty(n)
        yd = np.empty(n)
        dscr = np.empty(n)
        cscr = np.empty(1)
        full = np.empty(N_FULL)
        hist = np.empty(N_HIST)
        work = np.empty(N_WORK)
        ss = sstates[bi]
        uin = inputs[bi]
        cs = cstates[bi]
        for i in range(n - 1):
            s[i] = states[bi, i]
        s[n - 1] = cs[0]
        h = hstate[bi]
        errold = stats[bi, S_ERROLD]
        hj = 0
        j = 0
        while j < n_steps and stats[bi, S_FAILED] == 0.0:
            a = step0 + j
            seg = n_steps - j
            if sampled:
                if a % spc == 0:
                    controller(s, uin, cs, C, ytab)
                seg = min(seg, spc - a % spc)
            t_seg = seg * dt
            t_abs0 = a * dt
            # first stage at the segment start: also the outputs of grid point j
            _rhs(s, kk[0], cont, ss, uin, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl, rzr, full,
                 hist, outputs, work, C, ytab, cscr)  # fmt: skip
            stats[bi, S_CALLS] += 1.0
            hj = _emit(full_out, hist_out, np.int64(bi), np.int64(j), np.int64(hj), full, hist,
                       step0, decim)
            m = 1  # next grid point inside the segment (local index)
            tau = 0.0
            rejected = False
            while True:
                if h > hmax:
                    h = hmax
                h_prop = h
                last = False
                if tau + h >= t_seg:
                    h = t_seg - tau
                    last = True
                for i in range(n):
                    y0[i] = s[i]
                for st in range(1, ns):
                    for i in range(n):
                        acc = 0.0
                        for q in range(st):
                            acc += tab_a[st, q] * kk[q, i]
                        tmp[i] = y0[i] + h * acc
                    if st == ns - 1:
                        for i in range(n):
                            yd[i] = tmp[i]  # the propagated solution y1
                    _rhs(tmp, kk[st], cont, ss, uin, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl,
                         rzr, full, hist, no_outputs, work, C, ytab, cscr)  # fmt: skip
                stats[bi, S_CALLS] += ns - 1.0
                err = 0.0
                for i in range(n):
                    e = 0.0
                    for q in range(ns):
                        e += tab_e[q] * kk[q, i]
                    sk = atol + rtol * max(abs(y0[i]), abs(yd[i]))
                    r = h * e / sk
                    err += r * r
                err = math.sqrt(err / n)
                if err <= 1.0:
                    t_end = t_seg if last else tau + h
                    # dense output at the grid points inside (tau, t_end]
                    while m < seg and m * dt <= t_end:
                        th = (m * dt - tau) / h
                        if th > 1.0:
                            th = 1.0
                        th1 = 1.0 - th
                        if hermite:  # cubic Hermite on y0, y1, f0, f1 (3rd order)
                            h00 = (1.0 + 2.0 * th) * th1 * th1
                            h10 = th * th1 * th1
                            h01 = th * th * (3.0 - 2.0 * th)
                            h11 = -th * th * th1
                            for i in range(n):
                                tmp[i] = (h00 * y0[i] + h01 * yd[i]
                                          + h * (h10 * kk[0, i] + h11 * kk[ns - 1, i]))
                        else:  # Dormand-Prince continuous extension (DOPRI5 contd5)
                            for i in range(n):
                                r1 = yd[i] - y0[i]
                                r2 = h * kk[0, i] - r1
                                r3 = r1 - h * kk[ns - 1, i] - r2
                                r4 = 0.0
                                for q in range(ns):
                                    r4 += tab_d[q] * kk[q, i]
                                r4 *= h
                                tmp[i] = y0[i] + th * (r1 + th1 * (r2 + th * (r3 + th1 * r4)))
                        _rhs(tmp, dscr, cont, ss, uin, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl,
                             rzr, full, hist, outputs, work, C, ytab, cscr)  # fmt: skip
                        stats[bi, S_CALLS] += 1.0
                        hj = _emit(full_out, hist_out, np.int64(bi), np.int64(j + m),
                                   np.int64(hj), full, hist, step0, decim)
                        m += 1
                    for i in range(n):
                        s[i] = yd[i]
                        kk[0, i] = kk[ns - 1, i]
                    stats[bi, S_ACCEPTED] += 1.0
                    if stats[bi, S_HMIN_USED] == 0.0 or h < stats[bi, S_HMIN_USED]:
                        stats[bi, S_HMIN_USED] = h
                    if h > stats[bi, S_HMAX_USED]:
                        stats[bi, S_HMAX_USED] = h
                    nl = int(stats[bi, S_NLOG])
                    if nl < log_cap:
                        step_log[bi, 0, nl] = t_abs0 + t_end
                        step_log[bi, 1, nl] = h
                        stats[bi, S_NLOG] = nl + 1
                    fac = err**expo1 / max(errold, 1.0e-4) ** beta
                    fac = max(facc2, min(facc1, fac / safe))
                    hnew = h / fac
                    if rejected and hnew > h:
                        hnew = h
                    errold = max(err, 1.0e-4)
                    rejected = False
                    tau = t_end
                    if last:
                        # a step cut short to land on the segment end: keep the
                        # proposal from before the cut unless the error asks for less
                        h = hnew if hnew < h else max(hnew, h_prop)
                        break
                    h = hnew
                else:
                    stats[bi, S_REJECTED] += 1.0
                    fac11 = err**expo1 if err < 1.0e300 else 1.0e300
                    h = h / min(facc1, fac11 / safe)
                    rejected = True
                    if not (h >= hmin):
                        stats[bi, S_FAILED] = 1.0
                        stats[bi, S_FAIL_T] = t_abs0 + tau
                        break
            j += seg
        for i in range(n - 1):
            states[bi, i] = s[i]
        if cont:
            cs[0] = s[n - 1]
        hstate[bi] = h
        stats[bi, S_ERROLD] = errold
