"""Known answers: channel and film flows with their start-up series, and the Martin & Moyce (1952) surge front."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

TERMS = 200


def _sine_series(y: np.ndarray, t: float, height: float, nu: float, coeff) -> np.ndarray:
    """Σ b_n sin(nπy/H) exp(−n²π²νt/H²) for n = 1..TERMS."""
    n = np.arange(1, TERMS + 1)[:, None]
    decay = np.exp(-((n * np.pi / height) ** 2) * nu * t)
    return np.sum(coeff(n) * np.sin(n * np.pi * y[None, :] / height) * decay, axis=0)


def poiseuille(y: np.ndarray, t: float, force: float, nu: float, height: float) -> np.ndarray:
    """Start-up of plane Poiseuille flow from rest (Morris et al. 1997, eq. 21):
    u = f/(2ν)·y(H − y) − Σ_odd 4fH²/(νπ³n³)·sin(nπy/H)·exp(−n²π²νt/H²); y from one wall (m), t (s)."""
    steady = force / (2 * nu) * y * (height - y)
    if np.isinf(t):
        return steady
    odd = lambda n: np.where(n % 2 == 1, 4 * force * height**2 / (nu * np.pi**3 * n**3), 0.0)  # noqa: E731
    return steady - _sine_series(y, t, height, nu, odd)


def nusselt(y: np.ndarray, t: float, g_t: float, nu: float, depth: float) -> np.ndarray:
    """Start-up of film flow from rest (Nusselt 1916) under the along-plane gravity g_t (m/s²): a film of
    `depth` H on a no-slip plane, free on top, is the half of a Poiseuille channel of width 2H next to a wall
    (its free surface the channel's plane of symmetry), so u = g_t/ν·(H y − y²/2) when steady; y from the plane (m)."""
    return poiseuille(y, t, g_t, nu, 2 * depth)


def couette(y: np.ndarray, t: float, u_lower: float, u_upper: float, nu: float, height: float) -> np.ndarray:
    """Start-up of plane Couette flow from rest, walls suddenly moving at u_lower (y = 0) and u_upper (y = H):
    u = a + b·y − Σ b_n sin(nπy/H) exp(−n²π²νt/H²) with b_n the sine coefficients of the steady a + b·y."""
    a, b = u_lower, (u_upper - u_lower) / height
    steady = a + b * y
    if np.isinf(t):
        return steady
    coeff = lambda n: 2 / (n * np.pi) * (a * (1 - (-1.0) ** n) - b * height * (-1.0) ** n)  # noqa: E731
    return steady - _sine_series(y, t, height, nu, coeff)


def martin_moyce(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Surge front Z = x/a against T = t·sqrt(2g/a) (column of width a, height 2a)."""
    rows = [r for r in csv.reader(line for line in path.open() if not line.startswith("#"))]
    data = np.array([[float(v) for v in r] for r in rows[1:]])
    return data[:, 0], data[:, 1]


#: Martin & Moyce (1952), Fig. 3, as digitized in the PySPH project's dam-break data (shipped with augmpm).
MARTIN_MOYCE = Path(__file__).parent / "data" / "dam_break_martin_moyce_1952.csv"
