"""Compiled (numba) kernels of the simplified models of section 6 (RK4, fixed step).

This is the only compiled module of the simplified models.  ``pitch_plane.py`` and
``handling_model.py`` hold plain numpy implementations of the same equations built on
``strut.strut_force`` and ``tyre.vertical_force`` / ``tyre.pacejka89_lateral``; the tests
check the kernels against them.  The roll-and-pitch kernel (``rp_*``, ``roll_pitch.py``)
is checked against the pitch-plane kernel on identical tracks and against the full model
per tyre (test/test_roll_pitch.py).  The damper (cubic Hermite through the PCHIP slopes of
``strut.damper_knot_slopes``), the C1 stop ramp and the Pacejka '89 formula are the
compiled helpers of the full model (``_kernel._hermite``, ``_pen``, ``_pacejka``).

Strut parameter block (first ``N_SP`` entries of both parameter vectors): piston area,
polytropic exponent, atmospheric pressure, bump clearance/stiffness/cubic/smoothing,
rebound clearance/stiffness/cubic/smoothing.  Strut state per axle ``ss`` (2, 6): gas
constant K = V_s p_s^(1/n), static volume V_s, guard volume, dpsf (as in strut.py), and
for a coil spring its rate k (> 0; 0 for the gas spring) and the static strut load F_s
(``strut.coil_force_n``: F = F_s + k x).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._kernel import _hermite, _pacejka, _pen

# ---- strut parameter block ------------------------------------------------------------
S_AP, S_N, S_PATM, S_BCL, S_BK, S_BK3, S_BS, S_RCL, S_RK, S_RK3, S_RS = range(11)
N_SP = 11
# per axle: K, V_s, guard volume, dpsf (compression half), coil rate, static load, dpsf of
# the rebound half, anti-roll-bar stiffness N m/rad (the handling model's roll moment)
SS_K, SS_V, SS_VG, SS_DPSF, SS_KC, SS_F0, SS_DPSF_REB, SS_KARB = 0, 1, 2, 3, 4, 5, 6, 7
N_SS = 8

# ---- pitch-plane parameters (after the strut block) ----------------------------------
(PP_G, PP_A, PP_B, PP_MB, PP_IY, PP_MAF, PP_MAR, PP_KT, PP_CT, PP_DSTF, PP_DSTR, PP_XD, PP_XP) = (
    range(N_SP, N_SP + 13)
)
N_PP = N_SP + 13
# pitch-plane state: z_s, theta, z_af, z_ar and their rates (z up, theta nose down)
N_PP_STATE = 8
# pitch-plane outputs per step
O_ACC_D, O_ACC_P, O_FZF, O_FZR, O_ZS, O_TH, O_FSF, O_FSR = range(8)
N_PP_OUT = 8

# ---- handling parameters (after the strut block) ------------------------------------
(
    HP_G,
    HP_A,
    HP_B,
    HP_MB,
    HP_MV,
    HP_IX,
    HP_IZ,
    HP_H,
    HP_TS2,
    HP_U,
    HP_SHF,
    HP_SHR,
    HP_WAF,
    HP_WAR,
    HP_GRAV,
    HP_OWNSLIP,
) = range(N_SP, N_SP + 16)
N_HP = N_SP + 16
# handling state: y, psi, v, r, phi, phi_dot (phi positive = left side up)
N_H_STATE = 6
# handling outputs per step: roll, roll rate, lateral acceleration, 4 Fz, 4 Fy
OH_ROLL, OH_ROLL_RATE, OH_AY, OH_FZ0, OH_FY0 = 0, 1, 2, 3, 7
N_H_OUT = 11


@njit(cache=True, inline='always', error_model='numpy')
def _strut(x, xd, ss_ax, sp, dk, dv, ds):
    """4S4 strut force [N] (strut.strut_force: gas or coil spring + dpsf damper + stops)."""
    if ss_ax[SS_KC] > 0.0:  # coil spring (strut.coil_force_n)
        f_gas = ss_ax[SS_F0] + ss_ax[SS_KC] * x
    else:
        vc = ss_ax[SS_V] - sp[S_AP] * x
        vg = ss_ax[SS_VG]
        vv = vc if vc > vg else vg
        p = (ss_ax[SS_K] / vv) ** sp[S_N]
        if vc < vg:
            p -= sp[S_N] * p / vv * (vc - vg)
        f_gas = (p - sp[S_PATM]) * sp[S_AP]
    # compression (xd > 0) scales with dpsf, rebound with its own factor
    f_damp = -(ss_ax[SS_DPSF] if xd > 0.0 else ss_ax[SS_DPSF_REB]) * _hermite(-xd, dk, dv, ds)
    db = _pen(x - sp[S_BCL], sp[S_BS])
    dr = _pen(-x - sp[S_RCL], sp[S_RS])
    f_stop = (sp[S_BK] * db + sp[S_BK3] * db * db * db) - (
        sp[S_RK] * dr + sp[S_RK3] * dr * dr * dr
    )
    return f_gas + f_damp + f_stop


@njit(cache=True, inline='always', error_model='numpy')
def _tyre(defl, defl_d, k, c):
    """Point-follower tyre force [N] (tyre.vertical_force, paper eq. 19)."""
    if defl <= 0.0:
        return 0.0
    f = k * defl + c * defl_d
    return f if f > 0.0 else 0.0


@njit(cache=True, error_model='numpy')
def pp_deriv(s, ss, P, dk, dv, ds, zf, zfd, zr, zrd, d, out, want):
    """Pitch-plane state derivative, paper eqs. 15-24 (z up, theta nose down).

    Writes the derivative into ``d`` (N_PP_STATE,); ``out`` (N_PP_OUT,) if ``want``.
    """
    a = P[PP_A]
    b = P[PP_B]
    zs, th, zaf, zar = s[0], s[1], s[2], s[3]
    zsd, thd, zafd, zard = s[4], s[5], s[6], s[7]
    # strokes (compression positive), eqs. 17-18
    xf = zaf - (zs - a * th)
    xfd = zafd - (zsd - a * thd)
    xr = zar - (zs + b * th)
    xrd = zard - (zsd + b * thd)
    ff = _strut(xf, xfd, ss[0], P, dk, dv, ds)
    fr = _strut(xr, xrd, ss[1], P, dk, dv, ds)
    # one tyre of each axle, eq. 19 (contact only while compressed)
    tf = _tyre(P[PP_DSTF] + zf - zaf, zfd - zafd, P[PP_KT], P[PP_CT])
    tr = _tyre(P[PP_DSTR] + zr - zar, zrd - zard, P[PP_KT], P[PP_CT])
    g = P[PP_G]
    zsdd = (2.0 * ff + 2.0 * fr) / P[PP_MB] - g  # eq. 20
    thdd = (-a * 2.0 * ff + b * 2.0 * fr) / P[PP_IY]  # eq. 21 (nose-down positive)
    zafdd = (2.0 * tf - 2.0 * ff) / P[PP_MAF] - g  # eq. 15
    zardd = (2.0 * tr - 2.0 * fr) / P[PP_MAR] - g  # eq. 16
    d[0] = zsd
    d[1] = thd
    d[2] = zafd
    d[3] = zard
    d[4] = zsdd
    d[5] = thdd
    d[6] = zafdd
    d[7] = zardd
    if want:
        out[O_ACC_D] = zsdd - P[PP_XD] * thdd
        out[O_ACC_P] = zsdd - P[PP_XP] * thdd
        out[O_FZF] = tf
        out[O_FZR] = tr
        out[O_ZS] = zs
        out[O_TH] = th
        out[O_FSF] = ff
        out[O_FSR] = fr


@njit(cache=True, inline='always', error_model='numpy')
def _pp_acc(zs, th, zaf, zar, zsd, thd, zafd, zard, ssf, ssr, P, dk, dv, ds, zf, zfd, zr, zrd):
    """Accelerations and forces of the pitch-plane model as scalars (same as pp_deriv)."""
    a = P[PP_A]
    b = P[PP_B]
    ff = _strut(zaf - (zs - a * th), zafd - (zsd - a * thd), ssf, P, dk, dv, ds)
    fr = _strut(zar - (zs + b * th), zard - (zsd + b * thd), ssr, P, dk, dv, ds)
    tf = _tyre(P[PP_DSTF] + zf - zaf, zfd - zafd, P[PP_KT], P[PP_CT])
    tr = _tyre(P[PP_DSTR] + zr - zar, zrd - zard, P[PP_KT], P[PP_CT])
    g = P[PP_G]
    zsdd = (2.0 * ff + 2.0 * fr) / P[PP_MB] - g
    thdd = (-a * 2.0 * ff + b * 2.0 * fr) / P[PP_IY]
    zafdd = (2.0 * tf - 2.0 * ff) / P[PP_MAF] - g
    zardd = (2.0 * tr - 2.0 * fr) / P[PP_MAR] - g
    return zsdd, thdd, zafdd, zardd, tf, tr, ff, fr


@njit(cache=True, error_model='numpy', parallel=True)
def pp_integrate(states, sstates, P, dk, dv, ds, zf, zfd, zr, zrd, dt, n_steps, out):
    """RK4 over ``n_steps`` for every design (in place); road arrays at half steps.

    ``zf, zfd, zr, zrd`` have ``2 n_steps + 1`` samples at times ``k dt / 2``.  Outputs
    ``out[b, k, :]`` (step-major: one cache line per step) are taken at the start of step
    k (first RK stage, no extra cost).
    Same equations as :func:`pp_deriv`, written on scalars for speed.
    """
    # The loop over designs only calls the design's own integration: numba's parallel
    # passes then see a small loop body, and the first compile takes 22 s instead of
    # 61 s (handling: 18 s instead of 38 s; 2 shared cores) for the same bits.  A
    # gradient takes about 20 % longer (bench_gradient.py, 4 variables, 3 runs each:
    # ride 25-26 ms against 21-22 ms, handling 7.5-8.2 ms against 5.2-7.4 ms): a few
    # ms per iteration, against a minute saved at every install or change of the model.
    for bi in prange(states.shape[0]):
        _pp_integrate_design(np.int64(bi), states, sstates, P, dk, dv, ds, zf, zfd, zr, zrd, dt,
                             n_steps, out)


@njit(cache=True, error_model='numpy')
def _pp_integrate_design(bi, states, sstates, P, dk, dv, ds, zf, zfd, zr, zrd, dt, n_steps,
                         out):
    """RK4 of design ``bi`` for :func:`pp_integrate`."""
    h2 = 0.5 * dt
    h6 = dt / 6.0
    xd = P[PP_XD]
    xp = P[PP_XP]
    ssf = sstates[bi, 0]
    ssr = sstates[bi, 1]
    q0, q1, q2, q3, v0, v1, v2, v3 = (
        states[bi, 0],
        states[bi, 1],
        states[bi, 2],
        states[bi, 3],
        states[bi, 4],
        states[bi, 5],
        states[bi, 6],
        states[bi, 7],
    )
    for k in range(n_steps):
        j = 2 * k
        a0, a1, a2, a3, tf, tr, ff, fr = _pp_acc(
            q0,
            q1,
            q2,
            q3,
            v0,
            v1,
            v2,
            v3,
            ssf,
            ssr,
            P,
            dk,
            dv,
            ds,
            zf[j],
            zfd[j],
            zr[j],
            zrd[j],
        )
        out[bi, k, O_ACC_D] = a0 - xd * a1
        out[bi, k, O_ACC_P] = a0 - xp * a1
        out[bi, k, O_FZF] = tf
        out[bi, k, O_FZR] = tr
        out[bi, k, O_ZS] = q0
        out[bi, k, O_TH] = q1
        out[bi, k, O_FSF] = ff
        out[bi, k, O_FSR] = fr
        # stage 2
        p0, p1, p2, p3 = q0 + h2 * v0, q1 + h2 * v1, q2 + h2 * v2, q3 + h2 * v3
        w0, w1, w2, w3 = v0 + h2 * a0, v1 + h2 * a1, v2 + h2 * a2, v3 + h2 * a3
        b0, b1, b2, b3, _, _, _, _ = _pp_acc(
            p0,
            p1,
            p2,
            p3,
            w0,
            w1,
            w2,
            w3,
            ssf,
            ssr,
            P,
            dk,
            dv,
            ds,
            zf[j + 1],
            zfd[j + 1],
            zr[j + 1],
            zrd[j + 1],
        )
        # stage 3
        p0, p1, p2, p3 = q0 + h2 * w0, q1 + h2 * w1, q2 + h2 * w2, q3 + h2 * w3
        u0, u1, u2, u3 = v0 + h2 * b0, v1 + h2 * b1, v2 + h2 * b2, v3 + h2 * b3
        c0, c1, c2, c3, _, _, _, _ = _pp_acc(
            p0,
            p1,
            p2,
            p3,
            u0,
            u1,
            u2,
            u3,
            ssf,
            ssr,
            P,
            dk,
            dv,
            ds,
            zf[j + 1],
            zfd[j + 1],
            zr[j + 1],
            zrd[j + 1],
        )
        # stage 4
        p0, p1, p2, p3 = q0 + dt * u0, q1 + dt * u1, q2 + dt * u2, q3 + dt * u3
        y0, y1, y2, y3 = v0 + dt * c0, v1 + dt * c1, v2 + dt * c2, v3 + dt * c3
        d0, d1, d2, d3, _, _, _, _ = _pp_acc(
            p0,
            p1,
            p2,
            p3,
            y0,
            y1,
            y2,
            y3,
            ssf,
            ssr,
            P,
            dk,
            dv,
            ds,
            zf[j + 2],
            zfd[j + 2],
            zr[j + 2],
            zrd[j + 2],
        )
        q0 += h6 * (v0 + 2.0 * w0 + 2.0 * u0 + y0)
        q1 += h6 * (v1 + 2.0 * w1 + 2.0 * u1 + y1)
        q2 += h6 * (v2 + 2.0 * w2 + 2.0 * u2 + y2)
        q3 += h6 * (v3 + 2.0 * w3 + 2.0 * u3 + y3)
        v0 += h6 * (a0 + 2.0 * b0 + 2.0 * c0 + d0)
        v1 += h6 * (a1 + 2.0 * b1 + 2.0 * c1 + d1)
        v2 += h6 * (a2 + 2.0 * b2 + 2.0 * c2 + d2)
        v3 += h6 * (a3 + 2.0 * b3 + 2.0 * c3 + d3)
    states[bi, 0], states[bi, 1], states[bi, 2], states[bi, 3] = q0, q1, q2, q3
    states[bi, 4], states[bi, 5], states[bi, 6], states[bi, 7] = v0, v1, v2, v3


@njit(cache=True, inline='always', error_model='numpy')
def h_deriv(s, ss, P, dk, dv, ds, pc, slip, delta, d, out, want):
    """Handling-model derivative, paper eqs. 12-14 (ISO axes, phi positive left up).

    ``slip`` (4,) are the input slip angles FL, FR, RL, RR [rad] (used unless the
    own-slip option is set, then the slip angles follow from v, r and ``delta``).
    """
    a = P[HP_A]
    b = P[HP_B]
    ts2 = P[HP_TS2]
    u = P[HP_U]
    phi, phid = s[4], s[5]
    v, r = s[2], s[3]
    # struts: roll only; left struts extend when the left side rises
    xl = -ts2 * phi
    xld = -ts2 * phid
    f_fl = _strut(xl, xld, ss[0], P, dk, dv, ds)
    f_fr = _strut(-xl, -xld, ss[0], P, dk, dv, ds)
    f_rl = _strut(xl, xld, ss[1], P, dk, dv, ds)
    f_rr = _strut(-xl, -xld, ss[1], P, dk, dv, ds)
    fl = f_fl + f_rl
    fr = f_fr + f_rr
    # vertical tyre loads: static front/rear share of the side suspension force (+ axle)
    fz0 = P[HP_SHF] * fl + P[HP_WAF]
    fz1 = P[HP_SHF] * fr + P[HP_WAF]
    fz2 = P[HP_SHR] * fl + P[HP_WAR]
    fz3 = P[HP_SHR] * fr + P[HP_WAR]
    if P[HP_OWNSLIP] > 0.5:
        af = math.atan2(v + a * r, u) - delta
        ar = math.atan2(v - b * r, u)
        s0, s1, s2, s3 = af, af, ar, ar
    else:
        s0, s1, s2, s3 = slip[0], slip[1], slip[2], slip[3]
    fy0 = _pacejka(s0, fz0, pc)
    fy1 = _pacejka(s1, fz1, pc)
    fy2 = _pacejka(s2, fz2, pc)
    fy3 = _pacejka(s3, fz3, pc)
    sum_fy = fy0 + fy1 + fy2 + fy3
    ay = sum_fy / P[HP_MV]  # eq. 13
    rd = (a * (fy0 + fy1) - b * (fy2 + fy3)) / P[HP_IZ]  # eq. 12
    mx = (fl - fr) * ts2 + P[HP_H] * sum_fy * P[HP_MB] / P[HP_MV]  # eq. 14
    mx += (P[HP_GRAV] * P[HP_MB] * P[HP_G] * P[HP_H] * math.sin(phi)
           - (ss[0, SS_KARB] + ss[1, SS_KARB]) * phi)
    d[0] = u * math.sin(s[1]) + v * math.cos(s[1])
    d[1] = r
    d[2] = ay - u * r
    d[3] = rd
    d[4] = phid
    d[5] = mx / P[HP_IX]
    if want:
        out[OH_ROLL] = phi
        out[OH_ROLL_RATE] = phid
        out[OH_AY] = ay
        out[OH_FZ0] = fz0
        out[OH_FZ0 + 1] = fz1
        out[OH_FZ0 + 2] = fz2
        out[OH_FZ0 + 3] = fz3
        out[OH_FY0] = fy0
        out[OH_FY0 + 1] = fy1
        out[OH_FY0 + 2] = fy2
        out[OH_FY0 + 3] = fy3


@njit(cache=True, error_model='numpy', parallel=True)
def h_integrate(states, sstates, P, dk, dv, ds, pc, slip, delta, dt, n_steps, out):
    """RK4 of the handling model; ``slip`` (4, 2n+1) and ``delta`` (2n+1,) at half steps.

    Outputs ``out[b, k, :]`` (step-major) at the start of each step.
    """
    # As pp_integrate: the loop over designs only calls the design's own integration.
    for bi in prange(states.shape[0]):
        _h_integrate_design(np.int64(bi), states, sstates, P, dk, dv, ds, pc, slip, delta,
                            dt, n_steps, out)


@njit(cache=True, error_model='numpy')
def _h_integrate_design(bi, states, sstates, P, dk, dv, ds, pc, slip, delta, dt, n_steps,
                        out):
    """RK4 of design ``bi`` for :func:`h_integrate`."""
    # The four RK4 stages share one call site of the inlined h_deriv: numba inlines at
    # its IR level, and four inlined copies of the derivative made the first compile
    # take minutes (158 s here) for no speed-up over one copy in a stage loop.
    offsets = (0, 1, 1, 2)  # half-step sample of each stage's inputs
    fractions = (0.0, 0.5, 0.5, 1.0)  # stage point: s + fraction dt k_previous
    o = np.empty(N_H_OUT)  # per-design scratch (designs run in parallel)
    dummy = np.empty(N_H_OUT)
    tmp = np.empty(N_H_STATE)
    kk = np.empty((4, N_H_STATE))
    sl = np.empty(4)
    s = states[bi]
    ss = sstates[bi]
    for k in range(n_steps):
        j = 2 * k
        for stage in range(4):
            jj = j + offsets[stage]
            for c in range(4):
                sl[c] = slip[c, jj]
            if stage == 0:
                for i in range(N_H_STATE):
                    tmp[i] = s[i]
            else:
                step = fractions[stage] * dt
                for i in range(N_H_STATE):
                    tmp[i] = s[i] + step * kk[stage - 1, i]
            first = stage == 0
            h_deriv(tmp, ss, P, dk, dv, ds, pc, sl, delta[jj], kk[stage],
                    o if first else dummy, first)
            if first:
                for c in range(N_H_OUT):
                    out[bi, k, c] = o[c]
        for i in range(N_H_STATE):
            s[i] += dt / 6.0 * (kk[0, i] + 2.0 * kk[1, i] + 2.0 * kk[2, i] + kk[3, i])


# ---- roll-and-pitch ride model (after the strut block) -------------------------------
(
    RP_G,
    RP_A,
    RP_B,
    RP_MB,
    RP_IY,
    RP_IX,
    RP_MAF,
    RP_MAR,
    RP_IAF,
    RP_IAR,
    RP_KT,
    RP_CT,
    RP_DSTF,
    RP_DSTR,
    RP_T2,
    RP_TS2,
    RP_XD,
    RP_YD,
    RP_XP,
    RP_YP,
) = range(N_SP, N_SP + 20)
N_RP = N_SP + 20
# roll-and-pitch state: z_s, theta, phi, z_af, phi_af, z_ar, phi_ar, then their rates
N_RP_DOF = 7
N_RP_STATE = 2 * N_RP_DOF
# outputs per step: seat accelerations, 4 tyre forces (FL, FR, RL, RR), heave, pitch,
# roll, 4 strut forces
RO_ACC_D, RO_ACC_P, RO_FZ0, RO_ZS, RO_TH, RO_PHI, RO_FS0 = 0, 1, 2, 6, 7, 8, 9
N_RP_OUT = 13


@njit(cache=True, inline='always', error_model='numpy')
def rp_deriv(q, v, ss, P, dk, dv, ds, zc, zcd, acc, fz, fs):
    """Accelerations of the roll-and-pitch ride model (z up, pitch nose down, roll left up).

    ``q``, ``v``: positions and rates (N_RP_DOF,); ``zc``, ``zcd``: road and its rate under
    the corners FL, FR, RL, RR.  Writes ``acc`` (N_RP_DOF,), the tyre forces ``fz`` (4,)
    and the strut forces ``fs`` (4,).  The same vertical equations as the full model's
    kernel with one rigid body (no torsion) rolling about its own axis and no lateral
    motion.
    """
    a = P[RP_A]
    b = P[RP_B]
    t2 = P[RP_T2]
    ts2 = P[RP_TS2]
    g = P[RP_G]
    heave = 0.0
    pitch = 0.0
    roll = 0.0
    # per axle: tyre force sum, strut force sum, tyre and strut roll moments
    fz_f = fz_r = fs_f = fs_r = mt_f = mt_r = ms_f = ms_r = 0.0
    for i in range(4):
        axle = i // 2
        sy = 1.0 if i % 2 == 0 else -1.0
        xa = a if axle == 0 else -b
        za = q[3 + 2 * axle]
        pa = q[4 + 2 * axle]
        zad = v[3 + 2 * axle]
        pad = v[4 + 2 * axle]
        dst = P[RP_DSTF] if axle == 0 else P[RP_DSTR]
        yw = sy * t2
        ft = _tyre(dst + zc[i] - (za + yw * pa), zcd[i] - (zad + yw * pad), P[RP_KT], P[RP_CT])
        ysw = sy * ts2
        zb = q[0] - xa * q[1] + ysw * q[2]
        zbd = v[0] - xa * v[1] + ysw * v[2]
        f = _strut((za + ysw * pa) - zb, (zad + ysw * pad) - zbd, ss[axle], P, dk, dv, ds)
        fz[i] = ft
        fs[i] = f
        heave += f
        pitch -= xa * f
        roll += ysw * f
        if axle == 0:
            fz_f += ft
            fs_f += f
            mt_f += yw * ft
            ms_f += ysw * f
        else:
            fz_r += ft
            fs_r += f
            mt_r += yw * ft
            ms_r += ysw * f
    bar_f = ss[0, SS_KARB] * (q[2] - q[4])
    bar_r = ss[1, SS_KARB] * (q[2] - q[6])
    acc[0] = heave / P[RP_MB] - g
    acc[1] = pitch / P[RP_IY]
    acc[2] = (roll - bar_f - bar_r) / P[RP_IX]
    acc[3] = (fz_f - fs_f) / P[RP_MAF] - g
    acc[4] = (mt_f - ms_f + bar_f) / P[RP_IAF]
    acc[5] = (fz_r - fs_r) / P[RP_MAR] - g
    acc[6] = (mt_r - ms_r + bar_r) / P[RP_IAR]


@njit(cache=True, error_model='numpy', parallel=True)
def rp_integrate(states, sstates, P, dk, dv, ds, zc, zcd, dt, n_steps, out):
    """RK4 of the roll-and-pitch model over ``n_steps`` for every design (in place).

    ``zc, zcd`` (4, 2 n_steps + 1): road and its rate under each corner at half steps.
    Outputs ``out[b, k, :]`` are taken at the start of step k (first RK stage).
    """
    for bi in prange(states.shape[0]):
        _rp_integrate_design(np.int64(bi), states, sstates, P, dk, dv, ds, zc, zcd, dt,
                             n_steps, out)


@njit(cache=True, error_model='numpy')
def _rp_integrate_design(bi, states, sstates, P, dk, dv, ds, zc, zcd, dt, n_steps, out):
    """RK4 of design ``bi`` for :func:`rp_integrate`."""
    n = N_RP_DOF
    ss = sstates[bi]
    q = states[bi, :n].copy()
    v = states[bi, n:].copy()
    qs = np.empty(n)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    l2 = np.empty(n)
    l3 = np.empty(n)
    l4 = np.empty(n)
    fz = np.empty(4)
    fs = np.empty(4)
    z0 = np.empty(4)
    z0d = np.empty(4)
    z1 = np.empty(4)
    z1d = np.empty(4)
    h2 = 0.5 * dt
    for k in range(n_steps):
        j = 2 * k
        for c in range(4):
            z0[c] = zc[c, j]
            z0d[c] = zcd[c, j]
            z1[c] = zc[c, j + 1]
            z1d[c] = zcd[c, j + 1]
        rp_deriv(q, v, ss, P, dk, dv, ds, z0, z0d, k1, fz, fs)
        out[bi, k, RO_ACC_D] = k1[0] - P[RP_XD] * k1[1] + P[RP_YD] * k1[2]
        out[bi, k, RO_ACC_P] = k1[0] - P[RP_XP] * k1[1] + P[RP_YP] * k1[2]
        for c in range(4):
            out[bi, k, RO_FZ0 + c] = fz[c]
            out[bi, k, RO_FS0 + c] = fs[c]
        out[bi, k, RO_ZS] = q[0]
        out[bi, k, RO_TH] = q[1]
        out[bi, k, RO_PHI] = q[2]
        # stage 2: rates v + h/2 k1 (l2), positions q + h/2 v; the forces of stages 2-4
        # are not outputs, fz and fs take them
        for m in range(n):
            qs[m] = q[m] + h2 * v[m]
            l2[m] = v[m] + h2 * k1[m]
        rp_deriv(qs, l2, ss, P, dk, dv, ds, z1, z1d, k2, fz, fs)
        # stage 3
        for m in range(n):
            qs[m] = q[m] + h2 * l2[m]
            l3[m] = v[m] + h2 * k2[m]
        rp_deriv(qs, l3, ss, P, dk, dv, ds, z1, z1d, k3, fz, fs)
        # stage 4
        for m in range(n):
            qs[m] = q[m] + dt * l3[m]
            l4[m] = v[m] + dt * k3[m]
        for c in range(4):
            z0[c] = zc[c, j + 2]
            z0d[c] = zcd[c, j + 2]
        rp_deriv(qs, l4, ss, P, dk, dv, ds, z0, z0d, k4, fz, fs)
        for m in range(n):
            q[m] += dt / 6.0 * (v[m] + 2.0 * l2[m] + 2.0 * l3[m] + l4[m])
            v[m] += dt / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
    states[bi, :n] = q
    states[bi, n:] = v
