#!/usr/bin/env python3
"""Reference run of filterpy 2.0.0's UnscentedKalmanFilter on the paper helicopter model.

Usage: filterpy_ukf.py PARAMS.json OUT.csv

The model is re-implemented here from the physical parameters (numpy, independently of the Rust
code): zero-order hold of the diagonal rate dynamics plus Euler gyroscopic terms. The script
simulates a 2000-step run with a gamma fault at step 1000 (its own RNG), runs filterpy with
MerweScaledSigmaPoints(n, alpha, beta, kappa), and writes per step: inputs, measurement,
filterpy's posterior state and covariance. The Rust test feeds the same inputs and measurements
to ahcmon's UKF and compares. With "coast_every": k in the parameters, every k-th measurement is
lost: filterpy only predicts on that step, and its row carries the measurement as nan.
"""
import csv
import json
import sys

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter


def main():
    params_path, out_path = sys.argv[1], sys.argv[2]
    with open(params_path) as f:
        cfg = json.load(f)
    p = cfg["params"]
    dt = cfg["dt"]
    damping = np.array([p["l_p"], p["m_q"], p["n_r"]])
    phi = np.exp(damping * dt)
    zoh = (phi - 1.0) / damping
    gyro = np.array(p["gyro"])
    trim = np.array(p["trim_moment"])

    def fx(x, dt_, u):
        pr, qr, rr, gamma, delta = x
        lon_eff = gamma * u[2] + delta
        return np.array([
            phi[0] * pr + zoh[0] * (p["l_lat"] * u[1] + trim[0]) + dt * gyro[0] * qr * rr,
            phi[1] * qr + zoh[1] * (p["m_lon"] * lon_eff + trim[1]) + dt * gyro[1] * pr * rr,
            phi[2] * rr + zoh[2] * (p["n_ped"] * u[3] + p["n_col"] * u[0] + trim[2]) + dt * gyro[2] * pr * qr,
            gamma,
            delta,
        ])

    def hx(x):
        return x[:3].copy()

    steps = cfg["steps"]
    rng = np.random.default_rng(cfg["seed"])
    u_trim = np.array(cfg["u_trim"])
    t = np.arange(steps) * dt
    # Open-loop multisine excitation on the three cyclic/tail inputs around trim.
    u_seq = np.tile(u_trim, (steps, 1))
    u_seq[:, 1] += 0.004 * np.sin(2 * np.pi * 0.7 * t)
    u_seq[:, 2] += 0.01 * np.sin(2 * np.pi * 0.4 * t) + 0.005 * np.sin(2 * np.pi * 1.3 * t)
    u_seq[:, 3] += 0.01 * np.sin(2 * np.pi * 0.3 * t)
    x_true = np.array([0.0, 0.0, 0.0, 1.0, 0.0])
    ys = np.zeros((steps, 3))
    for k in range(steps):
        if k == cfg["fault_step"]:
            x_true[3] = cfg["fault_gamma"]
        x_true = fx(x_true, dt, u_seq[k])
        x_true[:3] += rng.normal(0.0, np.sqrt(cfg["process_var"]), 3)
        ys[k] = x_true[:3] + rng.normal(0.0, np.sqrt(cfg["measurement_var"]), 3)

    n = 5
    points = MerweScaledSigmaPoints(n, alpha=cfg["alpha"], beta=cfg["beta"], kappa=cfg["kappa"])
    ukf = UnscentedKalmanFilter(dim_x=n, dim_z=3, dt=dt, hx=hx, fx=fx, points=points)
    ukf.x = np.array(cfg["x0"], dtype=float)
    ukf.P = np.diag(cfg["p0_diag"]).astype(float)
    ukf.Q = np.diag(cfg["q_diag"]).astype(float)
    ukf.R = np.eye(3) * cfg["measurement_var"]
    with open(out_path, "w", newline="") as f:
        w = csv.writer(f)
        coast_every = cfg.get("coast_every", 0)
        for k in range(steps):
            ukf.predict(u=u_seq[k])
            y = ys[k]
            if coast_every and k % coast_every == coast_every - 1:
                y = np.full(3, np.nan)
            else:
                ukf.update(y)
            row = [k] + list(u_seq[k]) + list(y) + list(ukf.x) + list(ukf.P.reshape(-1))
            w.writerow([repr(float(v)) for v in row])


if __name__ == "__main__":
    main()
