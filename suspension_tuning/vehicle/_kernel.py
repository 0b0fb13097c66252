"""Compiled (numba) kernel of the full vehicle model: state derivative and RK4 stepping.

``_variable_step.py`` integrates the same ``deriv`` with an error-controlled
Dormand-Prince 5(4) pair instead.  ``full_model.derivative_numpy`` is an independent plain
numpy implementation of the same equations built on ``strut.py`` and ``tyre.py``; the test
suite checks the two against each other (test_full_model.py).

Strict IEEE arithmetic (no ``fastmath``) here, in ``_variable_step.py`` and in the
simplified models' kernels: with fastmath LLVM may fuse and reorder operations
differently when a function is compiled afresh and when it is loaded from numba's
cache, and the variable-step model amplifies such last-bit differences into its
numerical noise (f differed by 1 % between the first process on a machine and the
next).  Without it a design gives the same bits in every process.

Layouts (all float64):

State ``s`` (N_STATE,): X, Y, psi, u, v, r, then the positions zs, theta, phi_f, phi_r,
zaf, phiaf, zar, phiar, their 8 rates, then the road-wheel steer angle delta.
Corners: 0 FL, 1 FR, 2 RL, 3 RR.  ISO axes: x forward, y left, z up; roll positive =
left side up, pitch positive = nose down, yaw positive = to the left.

Strut state ``ss`` (4, N_SS) per corner: K_sum (sum of connected K_j = V_j p_j^(1/n)),
V_ref (connected gas volume at zero stroke), V_guard (guard volume), dpsf (compression
half of the damper table), dpsf of the rebound half, the anti-roll-bar stiffness of the
corner's axle (N m/rad; a design may set it, so it is per design, not in ``P``).

Inputs ``u_in`` (N_IN,): commanded steer angle, drive force.

Parameter vector ``P`` (N_PAR,), see ``P_*`` indices; ``Minv`` is the inverse of the
constant 11x11 mass matrix of the accelerations [vdot, rdot, udot, zs, theta, phi_f,
phi_r, zaf, phiaf, zar, phiar].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# ---- state indices --------------------------------------------------------------------
I_X, I_Y, I_PSI, I_U, I_V, I_R = 0, 1, 2, 3, 4, 5
I_ZS, I_TH, I_PHF, I_PHR, I_ZAF, I_PAF, I_ZAR, I_PAR = 6, 7, 8, 9, 10, 11, 12, 13
I_VEL0 = 14  # rates of the 8 positions above start here
I_DELTA = 22
N_STATE = 23
N_ACC = 11
COUPLED = np.array([0, 1, 5, 6, 8, 10])  # v, r, phi_f, phi_r, phiaf, phiar
UNCOUPLED = np.array([2, 3, 4, 7, 9])  # u, zs, theta, zaf, zar

# ---- strut state ----------------------------------------------------------------------
SS_KSUM, SS_VREF, SS_VGUARD, SS_DPSF, SS_DPSF_REB, SS_KARB = 0, 1, 2, 3, 4, 5
N_SS = 6

# ---- inputs ---------------------------------------------------------------------------
IN_DELTA_CMD, IN_FDRIVE = 0, 1
N_IN = 2

# ---- parameters -----------------------------------------------------------------------
(
    P_G,
    P_A,
    P_B,
    P_T2,
    P_TS2,
    P_MV,
    P_MS,
    P_MF,
    P_MR,
    P_MAF,
    P_MAR,
    P_HF,
    P_HR,
    P_HRCF,
    P_HRCR,
    P_RAX,
    P_KTOR,
    P_CTOR,
    P_KARBF,
    P_KARBR,
    P_KT,
    P_CT,
    P_DSTF,
    P_DSTR,
    P_AP,
    P_N,
    P_PATM,
    P_BCL,
    P_BK,
    P_BK3,
    P_BS,
    P_RCL,
    P_RK,
    P_RK3,
    P_RS,
    P_TAU,
    P_DMAX,
    P_FRR,
    P_XD,
    P_YD,
    P_XP,
    P_YP,
    P_IZ,
    P_XF,
    P_XR,
) = range(45)
N_PAR = 45

# ---- outputs --------------------------------------------------------------------------
# full-rate channels (metrics): seat accelerations, roll, roll rate, tyre normal forces
F_ACC_D, F_ACC_P, F_ROLL, F_ROLL_RATE, F_FZ0 = 0, 1, 2, 3, 4
N_FULL = 8
# decimated channels (histories)
(
    H_X,
    H_Y,
    H_PSI,
    H_U,
    H_AY,
    H_R,
    H_DELTA,
    H_DELTA_RATE,
    H_ROLL_F,
    H_ROLL_R,
) = range(10)
H_SLIP0 = 10  # 4 slip angles
H_FY0 = 14  # 4 lateral tyre forces
H_STROKE0 = 18  # 4 strut strokes
H_FSTRUT0 = 22  # 4 strut forces
H_PRESS0 = 26  # 4 gas pressures (absolute)
H_ROAD0 = 30  # 4 road elevations under the wheels
H_ZS, H_THETA = 34, 35
H_AZ = 36  # vertical acceleration of the body's centre of mass (gravity removed)
H_AX = 37  # longitudinal acceleration, udot - v r
H_THETA_RATE = 38  # pitch rate
N_HIST = 39
N_WORK = 50

# ---- internal controllers (driver and speed controller run inside the kernel) ---------
# Same algorithms as manoeuvre.PreviewDriver.steer and manoeuvre.SpeedController (checked
# against them in test_full_model.py); the reference path y_ref(x) is tabulated.
(
    C_STEER_ON,
    C_SPEED_ON,
    C_KLAT,
    C_TFF,
    C_TP,
    C_LPMIN,
    C_KFF,
    C_KUS,
    C_KR,
    C_DMAX,
    C_WB,
    C_VT,
    C_KP,
    C_KI,
    C_FLIM,
    C_TAB_X0,
    C_TAB_DX,
    C_TC,
    C_SPC,
) = range(19)
N_CTRL = 19


@njit(cache=True, inline='always')
def _hermite(v, knots, vals, slopes):
    n = knots.shape[0]
    if v <= knots[0]:
        return vals[0] + slopes[0] * (v - knots[0])
    if v >= knots[n - 1]:
        return vals[n - 1] + slopes[n - 1] * (v - knots[n - 1])
    i = 0
    while v > knots[i + 1]:
        i += 1
    h = knots[i + 1] - knots[i]
    t = (v - knots[i]) / h
    t2 = t * t
    t3 = t2 * t
    return (
        (2 * t3 - 3 * t2 + 1) * vals[i]
        + (t3 - 2 * t2 + t) * h * slopes[i]
        + (-2 * t3 + 3 * t2) * vals[i + 1]
        + (t3 - t2) * h * slopes[i + 1]
    )


@njit(cache=True, inline='always')
def _pen(d, s):
    if d <= 0.0:
        return 0.0
    if d < s:
        return d * d / (2.0 * s)
    return d - 0.5 * s


@njit(cache=True, inline='always')
def _pacejka(alpha, fz, pc):
    """ISO-sign Pacejka 89 lateral force [N]; alpha rad, fz N (camber 0)."""
    if fz <= 0.0:
        return 0.0
    if alpha == 0.0 and pc[9] == 0.0 and pc[10] == 0.0 and pc[12] == 0.0 and pc[13] == 0.0:
        return 0.0  # no slip and no shifts: exactly zero force (straight running)
    fzk = fz * 1.0e-3
    if fzk < 1.0e-6:
        fzk = 1.0e-6
    c = pc[0]
    d = pc[1] * fzk * fzk + pc[2] * fzk
    q = fzk / pc[4]
    bcd = pc[3] * 2.0 * q / (1.0 + q * q)  # = a3 sin(2 atan(Fz/a4))
    b = bcd / (c * d)
    e = pc[6] * fzk + pc[7]
    sh = pc[9] * fzk + pc[10]
    sv = pc[12] * fzk + pc[13]
    x1 = alpha * 57.29577951308232 + sh
    if x1 > 89.5:
        x1 = 89.5
    elif x1 < -89.5:
        x1 = -89.5
    bx = b * x1
    return -(d * math.sin(c * math.atan(bx - e * (bx - math.atan(bx)))) + sv)


@njit(cache=True, inline='always')
def _road(xw, x0, dx, zl, zr, side):
    """Elevation and slope of one track at distance xw (clamped at the ends)."""
    n = zl.shape[0]
    f = (xw - x0) / dx
    if f <= 0.0:
        i = 0
        t = 0.0
    elif f >= n - 1:
        i = n - 2
        t = 1.0
    else:
        i = int(f)
        t = f - i
    if side == 0:
        z0 = zl[i]
        z1 = zl[i + 1]
    else:
        z0 = zr[i]
        z1 = zr[i + 1]
    slope = (z1 - z0) / dx
    if f <= 0.0 or f >= n - 1:
        slope = 0.0
    return z0 + t * (z1 - z0), slope


@njit(cache=True)
def deriv(
    s, ss, u_in, P, Minv, pc, dk, dv, ds, rx0, rdx, rzl, rzr, ds_out, full, hist, want_out, work
):
    """State derivative ``ds_out = f(s)`` of one design; optional outputs.

    ``full`` (N_FULL,) and ``hist`` (N_HIST,) are written when ``want_out`` is True;
    ``work`` is scratch space of at least N_WORK floats (no allocation per call).
    """
    a = P[P_A]
    b = P[P_B]
    t2 = P[P_T2]
    ts2 = P[P_TS2]
    g = P[P_G]
    X = s[I_X]
    psi = s[I_PSI]
    u = s[I_U]
    v = s[I_V]
    r = s[I_R]
    delta = s[I_DELTA]
    cpsi = math.cos(psi)
    spsi = math.sin(psi)
    Xd = u * cpsi - v * spsi

    rhs = work[0:11]
    acc = work[11:22]
    fz = work[22:26]
    fy = work[26:30]
    alpha = work[30:34]
    fs = work[34:38]
    stroke = work[38:42]
    press = work[42:46]
    zroad = work[46:50]

    sum_fy_b_f = 0.0
    sum_fy_b_r = 0.0
    sum_fx_b = 0.0
    mz = 0.0
    fs_sum = 0.0
    pitch_m = 0.0
    roll_f = 0.0
    roll_r = 0.0
    fz_f_mom = 0.0
    fz_r_mom = 0.0
    fz_f_sum = 0.0
    fz_r_sum = 0.0
    fs_f_mom = 0.0
    fs_r_mom = 0.0
    fs_f_sum = 0.0
    fs_r_sum = 0.0
    cd = math.cos(delta)
    sd = math.sin(delta)
    for i in range(4):
        front = i < 2
        side = i % 2  # 0 left, 1 right
        sy = 1.0 if side == 0 else -1.0
        if front:
            xa = a
            za = s[I_ZAF]
            pa = s[I_PAF]
            zad = s[I_VEL0 + 4]
            pad = s[I_VEL0 + 5]
            phb = s[I_PHF]
            phbd = s[I_VEL0 + 2]
            dst = P[P_DSTF]
        else:
            xa = -b
            za = s[I_ZAR]
            pa = s[I_PAR]
            zad = s[I_VEL0 + 6]
            pad = s[I_VEL0 + 7]
            phb = s[I_PHR]
            phbd = s[I_VEL0 + 3]
            dst = P[P_DSTR]
        # road under the wheel (point on the track, enveloped beforehand)
        yw = sy * t2
        xw = X + xa * cpsi - yw * spsi
        xwd = Xd - (xa * spsi + yw * cpsi) * r
        zr_i, slope = _road(xw, rx0, rdx, rzl, rzr, side)
        zroad[i] = zr_i
        # tyre vertical
        defl = dst + zr_i - (za + yw * pa)
        defl_d = slope * xwd - (zad + yw * pad)
        f_t = 0.0
        if defl > 0.0:
            f_t = P[P_KT] * defl + P[P_CT] * defl_d
            if f_t < 0.0:
                f_t = 0.0
        fz[i] = f_t
        # strut
        ysw = sy * ts2
        zb = s[I_ZS] - xa * s[I_TH] + ysw * phb
        zbd = s[I_VEL0] - xa * s[I_VEL0 + 1] + ysw * phbd
        x_s = (za + ysw * pa) - zb
        xd_s = (zad + ysw * pad) - zbd
        stroke[i] = x_s
        vc = ss[i, SS_VREF] - P[P_AP] * x_s
        vg = ss[i, SS_VGUARD]
        vv = vc if vc > vg else vg
        p = math.exp(P[P_N] * math.log(ss[i, SS_KSUM] / vv))  # (K/V)^n
        if vc < vg:
            p -= P[P_N] * p / vv * (vc - vg)
        press[i] = p
        f_gas = (p - P[P_PATM]) * P[P_AP]
        # compression (xd_s > 0) scales with dpsf, rebound with its own factor
        f_damp = -(ss[i, SS_DPSF] if xd_s > 0.0 else ss[i, SS_DPSF_REB]) * _hermite(
            -xd_s, dk, dv, ds)
        db = _pen(x_s - P[P_BCL], P[P_BS])
        dr = _pen(-x_s - P[P_RCL], P[P_RS])
        f_stop = (P[P_BK] * db + P[P_BK3] * db * db * db) - (
            P[P_RK] * dr + P[P_RK3] * dr * dr * dr
        )
        f_s = f_gas + f_damp + f_stop
        fs[i] = f_s
        fs_sum += f_s
        pitch_m -= xa * f_s
        # tyre lateral
        vx = u - yw * r
        vy = v + xa * r
        if vx < 0.1:
            vx = 0.1
        al = math.atan2(vy, vx)
        if front:
            al -= delta
        alpha[i] = al
        f_y = _pacejka(al, f_t, pc)
        fy[i] = f_y
        f_rr = -P[P_FRR] * f_t
        if front:
            fxb = f_rr * cd - f_y * sd
            fyb = f_rr * sd + f_y * cd
            sum_fy_b_f += fyb
            fz_f_mom += sy * f_t
            fz_f_sum += f_t
            fs_f_mom += sy * f_s
            fs_f_sum += f_s
            roll_f += sy * f_s
        else:
            fxb = f_rr
            fyb = f_y
            sum_fy_b_r += fyb
            fz_r_mom += sy * f_t
            fz_r_sum += f_t
            fs_r_mom += sy * f_s
            fs_r_sum += f_s
            roll_r += sy * f_s
        sum_fx_b += fxb
        mz += xa * fyb - yw * fxb

    mf = P[P_MF]
    mr = P[P_MR]
    hf = P[P_HF]
    hr = P[P_HR]
    phf = s[I_PHF]
    phr = s[I_PHR]
    phfd = s[I_VEL0 + 2]
    phrd = s[I_VEL0 + 3]
    m_tor = P[P_KTOR] * (phr - phf) + P[P_CTOR] * (phrd - phfd)
    arb_f = ss[0, SS_KARB] * (phf - s[I_PAF])
    arb_r = ss[2, SS_KARB] * (phr - s[I_PAR])
    ur = u * r
    rhs[0] = sum_fy_b_f + sum_fy_b_r - P[P_MV] * ur
    rhs[1] = mz
    rhs[2] = u_in[IN_FDRIVE] + sum_fx_b + P[P_MV] * v * r
    rhs[3] = fs_sum - P[P_MS] * g
    rhs[4] = pitch_m
    rhs[5] = ts2 * roll_f + mf * g * hf * math.sin(phf) + m_tor - arb_f + mf * hf * ur
    rhs[6] = ts2 * roll_r + mr * g * hr * math.sin(phr) - m_tor - arb_r + mr * hr * ur
    rhs[7] = fz_f_sum - fs_f_sum - P[P_MAF] * g
    lf = P[P_HRCF] - P[P_RAX]
    lr = P[P_HRCR] - P[P_RAX]
    rhs[8] = t2 * fz_f_mom - ts2 * fs_f_mom + P[P_HRCF] * sum_fy_b_f + arb_f - P[P_MAF] * lf * ur
    rhs[9] = fz_r_sum - fs_r_sum - P[P_MAR] * g
    rhs[10] = t2 * fz_r_mom - ts2 * fs_r_mom + P[P_HRCR] * sum_fy_b_r + arb_r - P[P_MAR] * lr * ur

    # M (and so Minv) is block diagonal: lateral/yaw/roll DOFs coupled, the rest diagonal
    for k in range(6):
        kk = COUPLED[k]
        tot = 0.0
        for j in range(6):
            tot += Minv[kk, COUPLED[j]] * rhs[COUPLED[j]]
        acc[kk] = tot
    for k in range(5):
        kk = UNCOUPLED[k]
        acc[kk] = Minv[kk, kk] * rhs[kk]

    ds_out[I_X] = Xd
    ds_out[I_Y] = u * spsi + v * cpsi
    ds_out[I_PSI] = r
    ds_out[I_U] = acc[2]
    ds_out[I_V] = acc[0]
    ds_out[I_R] = acc[1]
    for k in range(8):
        ds_out[I_ZS + k] = s[I_VEL0 + k]
        ds_out[I_VEL0 + k] = acc[3 + k]
    dcmd = u_in[IN_DELTA_CMD]
    dmax = P[P_DMAX]
    if dcmd > dmax:
        dcmd = dmax
    elif dcmd < -dmax:
        dcmd = -dmax
    ddot = (dcmd - delta) / P[P_TAU]
    ds_out[I_DELTA] = ddot

    if want_out:
        zdd = acc[3]
        thdd = acc[4]
        full[F_ACC_D] = zdd - P[P_XD] * thdd + P[P_YD] * (acc[5] if P[P_XD] >= 0.0 else acc[6])
        full[F_ACC_P] = zdd - P[P_XP] * thdd + P[P_YP] * (acc[5] if P[P_XP] >= 0.0 else acc[6])
        wf = mf / (mf + mr)
        full[F_ROLL] = wf * phf + (1.0 - wf) * phr
        full[F_ROLL_RATE] = wf * phfd + (1.0 - wf) * phrd
        for i in range(4):
            full[F_FZ0 + i] = fz[i]
            hist[H_SLIP0 + i] = alpha[i]
            hist[H_FY0 + i] = fy[i]
            hist[H_STROKE0 + i] = stroke[i]
            hist[H_FSTRUT0 + i] = fs[i]
            hist[H_PRESS0 + i] = press[i]
            hist[H_ROAD0 + i] = zroad[i]
        hist[H_X] = X
        hist[H_Y] = s[I_Y]
        hist[H_PSI] = psi
        hist[H_U] = u
        hist[H_AY] = acc[0] + ur
        hist[H_R] = r
        hist[H_DELTA] = delta
        hist[H_DELTA_RATE] = ddot
        hist[H_ROLL_F] = phf
        hist[H_ROLL_R] = phr
        hist[H_ZS] = s[I_ZS]
        hist[H_THETA] = s[I_TH]
        hist[H_AZ] = zdd
        hist[H_AX] = acc[2] - v * r
        hist[H_THETA_RATE] = s[I_VEL0 + 1]


@njit(cache=True)
def y_table(x, ytab, x0, dx):
    """Linear interpolation of the tabulated reference path (clamped at the ends)."""
    n = ytab.shape[0]
    f = (x - x0) / dx
    if f <= 0.0:
        return ytab[0]
    if f >= n - 1:
        return ytab[n - 1]
    i = int(f)
    t = f - i
    return ytab[i] + t * (ytab[i + 1] - ytab[i])


@njit(cache=True)
def controller(s, uin, cstate, C, ytab):
    """Preview steering driver and PI speed controller (zero-order hold update)."""
    u = s[I_U]
    if C[C_STEER_ON] > 0.0:
        # manoeuvre.PreviewDriver.steer: preview error + curvature feed-forward + yaw rate
        lp = C[C_TP] * abs(u)
        if lp < C[C_LPMIN]:
            lp = C[C_LPMIN]
        x = s[I_X]
        x0 = C[C_TAB_X0]
        dx = C[C_TAB_DX]
        e = (
            y_table(x, ytab[0], x0, dx)
            - s[I_Y]
            + lp * math.sin(y_table(x, ytab[1], x0, dx) - s[I_PSI])
        )
        kappa = y_table(x + u * C[C_TFF], ytab[2], x0, dx)
        delta = (
            C[C_KFF] * (C[C_WB] + C[C_KUS] * u * u) * kappa
            + C[C_KLAT] * e
            + C[C_KR] * (u * kappa - s[I_R])
        )
        if delta > C[C_DMAX]:
            delta = C[C_DMAX]
        elif delta < -C[C_DMAX]:
            delta = -C[C_DMAX]
        uin[IN_DELTA_CMD] = delta
    if C[C_SPEED_ON] > 0.0:
        err = C[C_VT] - u
        raw = C[C_KP] * err + C[C_KI] * cstate[0]
        lim = C[C_FLIM]
        force = raw
        if force > lim:
            force = lim
        elif force < -lim:
            force = -lim
        uin[IN_FDRIVE] = force
        wind = (raw > lim and err > 0.0) or (raw < -lim and err < 0.0)
        if not wind:
            cstate[0] += err * C[C_TC]


@njit(cache=True, parallel=True)
def integrate(
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
    full_off,
    hist_off,
    cstates,
    C,
    ytab,
):
    """Advance every design ``n_steps`` fixed RK4 steps of ``dt`` (in place).

    If ``C[C_STEER_ON]`` or ``C[C_SPEED_ON]`` is set, the internal controllers update the
    held inputs at absolute steps divisible by ``C[C_SPC]`` (before that step).

    Outputs are evaluated at the start of each step (first RK stage, no extra cost):
    ``full_out[b, :, full_off + k]`` for every step k, and ``hist_out[b, :, j]`` at
    absolute steps ``step0 + k`` divisible by ``decim`` (index ``hist_off + ...``).
    Designs are independent (no coupling, same bits for a design in any batch).
    """
    n_b = states.shape[0]
    n = states.shape[1]
    for bi in prange(n_b):
        kk = np.empty((4, n))
        tmp = np.empty(n)
        full = np.empty(N_FULL)
        hist = np.empty(N_HIST)
        work = np.empty(N_WORK)
        s = states[bi]
        ss = sstates[bi]
        uin = inputs[bi]
        hj = hist_off
        cs = cstates[bi]
        spc = int(C[C_SPC])
        ctrl_on = C[C_STEER_ON] > 0.0 or C[C_SPEED_ON] > 0.0
        want = full_out.shape[2] > 0
        for k in range(n_steps):
            if ctrl_on and (step0 + k) % spc == 0:
                controller(s, uin, cs, C, ytab)
            for st in range(4):  # classical RK4 stages (one call site: deriv is inlined)
                if st == 0:
                    for j in range(n):
                        tmp[j] = s[j]
                elif st < 3:
                    for j in range(n):
                        tmp[j] = s[j] + 0.5 * dt * kk[st - 1, j]
                else:
                    for j in range(n):
                        tmp[j] = s[j] + dt * kk[2, j]
                deriv(
                    tmp,
                    ss,
                    uin,
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
                    kk[st],
                    full,
                    hist,
                    st == 0,
                    work,
                )
            if want:
                for c in range(N_FULL):
                    full_out[bi, c, full_off + k] = full[c]
            if (step0 + k) % decim == 0 and hist_out.shape[2] > 0:
                for c in range(N_HIST):
                    hist_out[bi, c, hj] = hist[c]
                hj += 1
            for j in range(n):
                s[j] = s[j] + dt / 6.0 * (kk[0, j] + 2.0 * kk[1, j] + 2.0 * kk[2, j] + kk[3, j])
