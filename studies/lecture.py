"""The lecture's printed numbers, transcribed digit for digit, and their check by computation.

Each printed value is compared with what steplab computes for the same quantity; a
value that differs by more than half a unit in its last printed digit is a misprint
(rounding cannot explain it). The lecture's projectile: m = 2.5 kg, p = (10, 0, 2) m,
mV = (19.2, 0, 72.5) kg m/s, g = 9.81 m/s^2, from t = 5 s.
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import simulate
from steplab.physics import lecture_state, projectile
from steplab.physics.scene import load_scene

from .tables import Table, markdown_table

#: "Explicit Euler Integration Example (2 of 2)": S after one step, numerical and exact,
#: rows (mV_x, mV_y, mV_z, p_x, p_y, p_z)
ONE_STEP = {
    0.2: {"numerical": ["19.2025", "0.0", "67.5951", "11.5362", "0.0", "7.8000"],
          "exact": ["19.2", "0.0", "67.5951", "11.5362", "0.0", "7.6038"]},
    0.1: {"numerical": ["19.2025", "0.0", "72.0476", "10.7681", "0.0", "4.9000"],
          "exact": ["19.2", "0.0", "72.0476", "10.1536", "0.0", "4.8510"]},
    0.01: {"numerical": ["19.2025", "0.0", "72.2549", "10.0768", "0.0", "2.2900"],
           "exact": ["19.2", "0.0", "72.2549", "10.0768", "0.0", "2.2895"]},
}
S_LABELS = ("mV_x", "mV_y", "mV_z", "p_x", "p_y", "p_z")

#: "Truncation Error Example (1 of 2)": numerical and exact positions and their difference
TRUNCATION_SLIDE = {
    0.2: {"numerical": ["11.5362", "0.0", "7.800"], "exact": ["11.5362", "0.0", "7.6038"],
          "error": ["0.0", "0.0", "0.1962"]},
    0.1: {"numerical": ["10.1536", "0.0", "4.9000"], "exact": ["10.1536", "0.0", "4.8510"],
          "error": ["0.0", "0.0", "0.049"]},
    0.01: {"numerical": ["10.0768", "0.0", "2.2900"], "exact": ["10.0768", "0.0", "2.2895"],
           "error": ["0.0", "0.0", "0.0005"]},
}

#: "Explicit Euler Integration - Computing Solution Over Time", dt = 0.2 s; columns
#: p, mV, F, V (x, y, z each)
MULTI_STEP_COLUMNS = ("p_x", "p_y", "p_z", "mV_x", "mV_y", "mV_z", "F_x", "F_y", "F_z", "V_x", "V_y", "V_z")
MULTI_STEP = {
    5.00: "10.00 0.00 2.00 19.20 0.00 72.50 0.00 0.00 -24.53 7.68 0.00 29.00",
    5.20: "11.54 0.00 7.80 19.20 0.00 67.60 0.00 0.00 -24.53 7.68 0.00 27.04",
    5.40: "13.07 0.00 13.21 19.20 0.00 62.69 0.00 0.00 -24.53 7.68 0.00 25.08",
    5.60: "14.61 0.00 18.22 19.20 0.00 57.79 0.00 0.00 -24.53 7.68 0.00 23.11",
    10.40: "51.48 0.00 20.87 19.20 0.00 -59.93 0.00 0.00 -24.53 7.68 0.00 -23.97",
}

#: why a flagged value is wrong, where computation alone cannot say
EXPLANATIONS = {
    "mV_x": "F_x = 0, so the x momentum cannot change from 19.2; the exact column beside it prints 19.2",
    "one step, dt = 0.1 s, numerical mV_z": "72.5 - 0.1 x 24.525 = 70.0475: a digit slip (72.0 for 70.0)",
    "one step, dt = 0.1 s, exact mV_z": "momentum under a constant force is exact in Euler; the same slip as "
                                        "the numerical column",
    "one step, dt = 0.1 s, exact p_x": "V_x is constant, so exact and numerical p_x agree (10.768); 10.1536 "
                                       "is not a value of this problem at all",
    "truncation slide, dt = 0.1 s, numerical p_x": "copied from the misprinted exact column of the "
                                                   "previous slide",
    "truncation slide, dt = 0.1 s, exact p_x": "copied from the misprinted exact column of the previous slide",
    "p_x": "the table uses V_x = 7.68 m/s; the printed digits match 7.681 m/s",
    "mV_z": "F_z = m g = -2.5 x 9.81 = -24.525 N, so mV_z = 72.5 - 24.525 dt exactly",
    "t = 10.4 s, p_x": "27 steps of 0.2 x 7.68 m from 10 m give 51.472 m",
}


def _decimals(text: str) -> int:
    return len(text.split(".")[1]) if "." in text else 0


def _check(where: str, printed: str, computed: float, misprints: list, key: str) -> None:
    tolerance = 0.5 * 10.0 ** -_decimals(printed) + 1e-9
    if abs(float(printed) - computed) > tolerance:
        note = EXPLANATIONS.get(where, EXPLANATIONS.get(key, ""))
        reason = "differs by more than the rounding of its printed digits"
        misprints.append({"where": where, "printed": printed, "computed": round(float(computed), 6),
                          "note": f"{reason}; {note}" if note else reason})


def lecture_check() -> dict:
    """Recompute the lecture's explicit Euler tables; return the table and the misprints."""
    scene = load_scene("projectile")
    m = float(scene.model.masses[0])
    g = np.asarray(scene.model.constant_acceleration)[0]
    misprints, table = [], []

    for dt, printed in ONE_STEP.items():
        traj = simulate(scene.model, "euler", scene.y0, scene.t_start, scene.t_start + dt, dt)
        numerical = lecture_state(traj.y[-1], [m]).ravel()
        p, v = projectile(scene.t_start + dt, scene.y0[0], scene.y0[1], g, scene.t_start)
        exact = lecture_state(np.stack([p, v]), [m]).ravel()
        for column, values in (("numerical", numerical), ("exact", exact)):
            for label, text, value in zip(S_LABELS, printed[column], values):
                _check(f"one step, dt = {dt:g} s, {column} {label}", text, value, misprints, label)
        table.append({"dt": dt, "z_numerical": float(numerical[5]), "z_exact": float(exact[5]),
                      "error": float(numerical[5] - exact[5])})
        slide = TRUNCATION_SLIDE[dt]
        for column, values in (("numerical", numerical[3:]), ("exact", exact[3:]),
                               ("error", numerical[3:] - exact[3:])):
            for label, text, value in zip(("x", "y", "z"), slide[column], values):
                where = f"truncation slide, dt = {dt:g} s, {column} p_{label}"
                _check(where, text, value, misprints, f"p_{label}")

    traj = simulate(scene.model, "euler", scene.y0, scene.t_start, 10.4, 0.2)
    rows = []
    for t, line in MULTI_STEP.items():
        k = int(round((t - scene.t_start) / 0.2))
        q, v = traj.y[k, 0, 0], traj.y[k, 1, 0]
        values = np.concatenate([q, m * v, m * g, v])
        for label, text, value in zip(MULTI_STEP_COLUMNS, line.split(), values):
            _check(f"t = {t:g} s, {label}", text, value, misprints, label)
        rows.append({"t": t, "p": q.tolist(), "mV": (m * v).tolist()})

    # "x = x + (v + a*t)*t" (Newtonian Physics 2 of 3) is neither the exact update nor explicit
    # Euler: it is the semi-implicit Euler position step, with a t^2 where the closed form has a t^2 / 2.
    dt = 0.2
    formula = scene.y0[0, 0, 2] + (scene.y0[1, 0, 2] + g[2] * dt) * dt
    semi = simulate(scene.model, "semi-implicit-euler", scene.y0, scene.t_start, scene.t_start + dt, dt)
    exact_z = projectile(scene.t_start + dt, scene.y0[0], scene.y0[1], g, scene.t_start)[0][0, 2]
    misprints.append({
        "where": "Newtonian Physics (2 of 3), x = x + (v + a*t)*t", "printed": "x + v t + a t^2",
        "computed": round(float(exact_z), 6),
        "note": f"for the lecture's projectile and t = 0.2 s it gives z = {formula:.4f} m (the semi-implicit "
                f"Euler step, {float(semi.y[-1, 0, 0, 2]):.4f} m), not the exact {exact_z:.4f} m: the closed "
                "form has a t^2 / 2",
    })
    return {"lecture_table": table, "multi_step": rows, "misprints": misprints}


# --- the paper's table of the lecture's errors ---------------------------------------


def _errors_to_print(record: dict) -> list[dict]:
    """The lecture errors a study found that the paper lists: real errors, not checks it passed."""
    return [{k: e[k] for k in ("where", "printed", "correct", "evidence")} for e in record["lecture_errors"]
            if e.get("is_error", True) and not e["correct"].startswith("checked")]


def lecture_errors_table(data: list[dict]) -> str:
    rows = [[e["where"], e["printed"], e["correct"], e["evidence"]] for e in data]
    return markdown_table(["where", "printed", "correct", "evidence (computed by steplab)"], rows)


#: one table of the lecture's errors, given by each study that checks a chapter (restitution:
#: the response chapter, tunnelling: the detection chapter), their rows joined
LECTURE_ERRORS_TABLE = Table("lecture_errors", _errors_to_print, lecture_errors_table)
