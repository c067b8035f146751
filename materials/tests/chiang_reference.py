#!/usr/bin/env python3
"""Reference values of the Chiang et al. 2016 hair model, computed independently of tress in
40-digit arithmetic with the exact modified Bessel function I0 (mpmath), for
tests/chiang_reference.rs.

Conventions (pbrt-v4's, which tress follows): directions in the fiber frame, x along the fiber;
sin(theta) = w.x, phi = atan2(w.z, w.y); h in [-1, 1] across the fiber; the scale tilt alpha
rotates the R lobe by -2 alpha, TT by +alpha and TRT by +4 alpha; the azimuthal lobe p is a
logistic trimmed to [-pi, pi] about Phi(p) = 2 p gamma_t - 2 gamma_o + p pi; the residual lobe
p = 3 is uniform in phi. eval = sum_p A_p M_p N_p (no division by cos theta_i), and
pdf = sum_p w_p M_p N_p with w_p = luminance(A_p) / sum luminance (Rec. 709 weights).

Usage: python3 materials/tests/chiang_reference.py > materials/tests/data/chiang_reference.csv
"""

import itertools

import mpmath as mp

mp.mp.dps = 40
PI = mp.pi
EUMELANIN = (0.419, 0.697, 1.37)
LUMINANCE = (0.2126, 0.7152, 0.0722)


def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance entering a dielectric of index eta from outside."""
    cos_i = min(max(cos_i, mp.mpf(0)), mp.mpf(1))
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = mp.sqrt(1 - sin_t2)
    r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return (r_parl**2 + r_perp**2) / 2


def longitudinal(v, sin_i, cos_i, sin_o, cos_o):
    """The vMF lobe M_p: exp(-b) I0(a) / (2 v sinh(1/v)), exact I0."""
    a = cos_i * cos_o / v
    b = sin_i * sin_o / v
    return mp.exp(-b) * mp.besseli(0, a) / (2 * v * mp.sinh(1 / v))


def logistic(x, s):
    e = mp.exp(-abs(x) / s)
    return e / (s * (1 + e) ** 2)


def logistic_cdf(x, s):
    return 1 / (1 + mp.exp(-x / s))


def trimmed_logistic(x, s):
    return logistic(x, s) / (logistic_cdf(PI, s) - logistic_cdf(-PI, s))


def wrap(x):
    while x > PI:
        x -= 2 * PI
    while x < -PI:
        x += 2 * PI
    return x


def chiang(beta_m, beta_n, alpha_deg, eta, sigma_a, theta_o, theta_i, dphi, h):
    """(eval RGB, pdf) of the Chiang model for these parameters and arguments."""
    beta_m, beta_n, eta = mp.mpf(beta_m), mp.mpf(beta_n), mp.mpf(eta)
    theta_o, theta_i, dphi, h = (mp.mpf(x) for x in (theta_o, theta_i, dphi, h))
    sin_o, cos_o = mp.sin(theta_o), mp.cos(theta_o)
    sin_i, cos_i = mp.sin(theta_i), mp.cos(theta_i)
    v0 = (0.726 * beta_m + 0.812 * beta_m**2 + 3.7 * beta_m**20) ** 2
    v = [v0, v0 / 4, 4 * v0, 4 * v0]
    s = mp.sqrt(PI / 8) * (0.265 * beta_n + 1.194 * beta_n**2 + 5.372 * beta_n**22)

    gamma_o = mp.asin(h)
    sin_t = sin_o / eta
    cos_t = mp.sqrt(1 - sin_t**2)
    eta_p = mp.sqrt(eta**2 - sin_o**2) / cos_o
    sin_gt = h / eta_p
    gamma_t = mp.asin(sin_gt)
    cos_gt = mp.cos(gamma_t)
    transmittance = [mp.exp(-mp.mpf(sa) * 2 * cos_gt / cos_t) for sa in sigma_a]
    f = fresnel(cos_o * mp.cos(gamma_o), eta)
    ap = [[f] * 3]
    ap.append([(1 - f) ** 2 * t for t in transmittance])
    ap.append([a * t * f for a, t in zip(ap[1], transmittance)])
    ap.append([a * f * t / (1 - f * t) for a, t in zip(ap[2], transmittance)])
    lum = [sum(w * c for w, c in zip(LUMINANCE, a)) for a in ap]
    weights = [l / sum(lum) for l in lum]

    alpha = mp.radians(alpha_deg)
    tilt = {0: -2 * alpha, 1: alpha, 2: 4 * alpha, 3: mp.mpf(0)}
    value, pdf = [mp.mpf(0)] * 3, mp.mpf(0)
    for p in range(4):
        # theta_o rotated by the lobe's tilt.
        sin_op = sin_o * mp.cos(tilt[p]) + cos_o * mp.sin(tilt[p])
        cos_op = abs(cos_o * mp.cos(tilt[p]) - sin_o * mp.sin(tilt[p]))
        m = longitudinal(v[p], sin_i, cos_i, sin_op, cos_op)
        if p < 3:
            n = trimmed_logistic(wrap(dphi - (2 * p * gamma_t - 2 * gamma_o + p * PI)), s)
        else:
            n = 1 / (2 * PI)
        value = [acc + a * m * n for acc, a in zip(value, ap[p])]
        pdf += weights[p] * m * n
    return value, pdf


def main():
    fibers = [
        # beta_m, beta_n, alpha (degrees), eta, sigma_a (RGB), label
        (0.3, 0.3, 2.0, 1.55, tuple(1.3 * c for c in EUMELANIN), "brown"),
        (0.2, 0.5, 3.0, 1.6, (0.0, 0.0, 0.0), "white"),
        (0.1, 0.15, 0.0, 1.55, tuple(0.3 * c for c in EUMELANIN), "narrow blond"),
    ]
    hs = [-0.9, -0.3, 0.0, 0.5, 0.95]
    thetas_o = [-1.0, 0.0, 0.4, 1.2]
    thetas_i = [-0.8, -0.2, 0.35, 1.1]
    phis = [-2.5, -0.6, 0.0, 1.0, 3.0]
    print("beta_m,beta_n,alpha,eta,sa_r,sa_g,sa_b,theta_o,theta_i,phi,h,f_r,f_g,f_b,pdf")
    for (bm, bn, al, eta, sa, _), h, to, ti, phi in itertools.product(
        fibers, hs, thetas_o, thetas_i, phis
    ):
        value, pdf = chiang(bm, bn, al, eta, sa, to, ti, phi, h)
        row = [bm, bn, al, eta, *sa, to, ti, phi, h]
        print(",".join(repr(float(x)) for x in row) + "," +
              ",".join(mp.nstr(x, 17) for x in [*value, pdf]))


if __name__ == "__main__":
    main()
