"""Where a rigid-object recording and its model disagree, step by step.

The model steps once from every recorded state; the one-step velocity error
|v_model(k+1 | x_k) - v_data(k+1)| (linear, m/s, world) is compared with its level in
free flight (where the model is exact up to sensing noise). Each sample gets a phase
from the data alone:
  flight   the lowest corner more than CONTACT_GAP above the table
  impact   in contact, within IMPACT_STEPS of arriving from flight
  sliding  in contact, horizontal speed above REST_SPEED
  rest     in contact and slower than that
Mismatch windows are runs of samples whose error is above 3x the flight level. Contact
modes: the model is "in contact" when its impulse is nonzero; the data when the lowest
corner is near the table and the body's acceleration departs from gravity.
"""
from __future__ import annotations

import numpy as np

from adaptive_c3.models.rigid_object import plant_state, quat_to_matrix

CONTACT_GAP = 0.004      # m
IMPACT_STEPS = 4
REST_SPEED = 0.05        # m/s
OFF_BALLISTIC = 3.0      # m/s^2 departure from free fall that counts as contact in the data
PHASES = ("flight", "impact", "sliding", "rest")


def lowest_corner(x_rec: np.ndarray, half_size, table_height: float) -> np.ndarray:
    """[T] height of the lowest box corner above the table, m."""
    corners = np.array(np.meshgrid(*[[-h, h] for h in half_size])).reshape(3, -1).T
    R = quat_to_matrix(x_rec[:, 3:7])
    z = x_rec[:, 2:3] + np.einsum("tj,cj->tc", R[:, 2, :], corners)
    return z.min(axis=1) - table_height


def phases(x_rec: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """[T] index into PHASES per sample."""
    contact = gap < CONTACT_GAP
    out = np.where(contact, 3, 0)
    speed = np.linalg.norm(x_rec[:, 7:9], axis=1)
    out[contact & (speed > REST_SPEED)] = 2
    since_flight = np.full(len(x_rec), 10 ** 6)
    last = -10 ** 6
    for k in range(len(x_rec)):
        if not contact[k]:
            last = k
        since_flight[k] = k - last
    out[contact & (since_flight <= IMPACT_STEPS)] = 1
    return out


def locate(model, episodes: dict, dt: float, g: float = 9.81, max_windows: int = 20) -> dict:
    """Mismatch windows, per-phase errors and contact-mode agreement of `model`
    (a RigidObjectModel) on {episode id: (t, x_rec)}."""
    from adaptive_c3.tools.diagnosis.backends.rigid_model import RigidModelError
    p = model.params
    rows = []
    for e, (t, x) in episodes.items():
        gap = lowest_corner(x, p.half_size, p.table_height)
        ph = phases(x, gap)
        xp = plant_state(x)
        acc = np.zeros(len(x))
        acc[:-1] = np.linalg.norm((x[1:, 7:10] - x[:-1, 7:10]) / dt - [0, 0, -g], axis=1)
        for k in range(len(x) - 1):
            try:
                x_next, lam = model.step(xp[k])
            except (RigidModelError, ValueError):
                continue
            err = float(np.linalg.norm(x_next[10:13] - x[k + 1, 7:10]))
            data_contact = gap[k] < CONTACT_GAP and acc[k] > OFF_BALLISTIC
            rows.append((e, t[k], ph[k], err, bool(np.any(lam > 1e-9)), data_contact))
    if not rows:
        return dict(noise_floor_mps=None, phases={}, windows=[], contact_modes={})
    ep = np.array([r[0] for r in rows])
    tt = np.array([r[1] for r in rows])
    ph = np.array([r[2] for r in rows])
    err = np.array([r[3] for r in rows])
    mc = np.array([r[4] for r in rows])
    dc = np.array([r[5] for r in rows])
    flight = err[ph == 0]
    floor = float(np.percentile(flight, 95)) if flight.size else float(np.median(err))
    by_phase = {}
    for i, name in enumerate(PHASES):
        sel = ph == i
        if sel.any():
            by_phase[name] = dict(samples=int(sel.sum()),
                                  one_step_velocity_error_mps_median=float(np.median(err[sel])),
                                  one_step_velocity_error_mps_p90=float(np.percentile(err[sel], 90)),
                                  above_floor_fraction=float(np.mean(err[sel] > 3 * floor)))
    contact_modes = {name: dict(both=int(np.sum((ph == i) & mc & dc)),
                                model_only=int(np.sum((ph == i) & mc & ~dc)),
                                data_only=int(np.sum((ph == i) & ~mc & dc)),
                                neither=int(np.sum((ph == i) & ~mc & ~dc)))
                     for i, name in enumerate(PHASES) if np.any(ph == i)}
    bad = err > 3 * floor
    windows = []
    k = 0
    while k < len(rows):
        if not bad[k]:
            k += 1
            continue
        j = k
        while j + 1 < len(rows) and bad[j + 1] and ep[j + 1] == ep[k]:
            j += 1
        seg = slice(k, j + 1)
        counts = np.bincount(ph[seg], minlength=len(PHASES))
        windows.append(dict(episode=int(ep[k]), start=float(tt[k]), end=float(tt[j]),
                            phase=PHASES[int(np.argmax(counts))],
                            mean_error_mps=float(err[seg].mean()),
                            model_contact_steps=int(mc[seg].sum()),
                            data_contact_steps=int(dc[seg].sum())))
        k = j + 1
    windows.sort(key=lambda w: -w["mean_error_mps"] * (w["end"] - w["start"] + dt))
    return dict(noise_floor_mps=floor, phases=by_phase, windows=windows[:max_windows],
                windows_total=len(windows), contact_modes=contact_modes)
