#!/usr/bin/env python3
"""Time filterpy 2.0.0's UKF per step on the paper helicopter problem (n = 5, same model, noise
and inputs as benches/filters.rs), for the >= 100x comparison. Prints microseconds per step."""
import time

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

DT = 0.02
K_M = 54.0 + 80.44 * 0.235
IXX, IYY, IZZ = 0.18, 0.34, 0.28
DAMP = np.array([-K_M * 0.1 / IXX, -K_M * 0.1 / IYY, -3.0])
PHI = np.exp(DAMP * DT)
ZOH = (PHI - 1.0) / DAMP
L_LAT, M_LON, N_PED, N_COL = K_M * 4.2 / IXX, K_M * 4.2 / IYY, 107.0, -20.0
GYRO = [(IYY - IZZ) / IXX, (IZZ - IXX) / IYY, (IXX - IYY) / IZZ]
U_TRIM = np.array([0.1, 0.0, -0.05, 0.05])
TRIM = [-L_LAT * U_TRIM[1], -M_LON * U_TRIM[2], -(N_PED * U_TRIM[3] + N_COL * U_TRIM[0])]


def fx(x, dt, u):
    p, q, r, g, d = x
    return np.array([
        PHI[0] * p + ZOH[0] * (L_LAT * u[1] + TRIM[0]) + DT * GYRO[0] * q * r,
        PHI[1] * q + ZOH[1] * (M_LON * (g * u[2] + d) + TRIM[1]) + DT * GYRO[1] * p * r,
        PHI[2] * r + ZOH[2] * (N_PED * u[3] + N_COL * u[0] + TRIM[2]) + DT * GYRO[2] * p * q,
        g, d])


def hx(x):
    return x[:3].copy()


def main():
    steps = 2000
    rng = np.random.default_rng(1)
    ukf = UnscentedKalmanFilter(5, 3, DT, hx, fx, MerweScaledSigmaPoints(5, 1.0, 2.0, 0.0))
    ukf.x = np.array([0, 0, 0, 1.0, 0])
    ukf.P = np.diag([1e-4, 1e-4, 1e-4, 1e-2, 1e-4])
    ukf.Q = np.diag([1e-4, 1e-4, 1e-4, 1e-6, 2.5e-9])
    ukf.R = np.eye(3) * 2.89e-6
    us = [U_TRIM + [0, 0, 0.01 * np.sin(0.05 * k), 0] for k in range(steps)]
    ys = rng.normal(0, 0.01, (steps, 3))
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for k in range(steps):
            ukf.predict(u=us[k])
            ukf.update(ys[k])
        best = min(best, (time.perf_counter() - t0) / steps * 1e6)
    print(f"filterpy UKF step (n=5): {best:.1f} us")


if __name__ == "__main__":
    main()
