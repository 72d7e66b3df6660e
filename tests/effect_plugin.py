"""The one invented effect the effect-plugin tests install from outside the package: a module and its
``*.dist-info`` folder (METADATA, entry_points.txt), the way pip leaves a package, found through the
``mountcal.effects`` entry points with nothing in mountcal edited. tests/test_effect_registry.py uses it in
process (on ``sys.path``), tests/test_effects.py through the command line (on ``PYTHONPATH``)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mountcal.core.conventions import FloatArray
from mountcal.estimate import effects as registry

SRC = Path(__file__).resolve().parents[1] / "src"
MODULE = "mc_quadratic"

# Every hook a test relies on: unit, spec_limits and label (the summary, the systematic σ and its notes),
# correct (rotate undoes the fitted nonlinearity).
SOURCE = '''
"""An invented effect: a quadratic nonlinearity of the horizontal axes, a_k = p_k + q_k p_k² (k = x, y)."""
import numpy as np
from mountcal.estimate.effects.base import BaseEffect


class Quadratic(BaseEffect):
    name = "quadratic"
    meaning = "a quadratic nonlinearity of the x and y axes, 2 values (1/(m/s²))"
    order = 15
    report_key = "quadratic_per_mps2"
    unit = "1/(m/s²)"

    def parameters(self, table):
        return ("quad_x", "quad_y")

    def initial(self, table, g_mps2):
        return np.zeros(2)

    def apply(self, table, values, p, g0_mps2):
        q = np.array([values[0], values[1], 0.0])
        d_values = np.zeros((len(p), 3, 2))
        d_values[:, 0, 0], d_values[:, 1, 1] = p[:, 0] ** 2, p[:, 1] ** 2
        d_p = np.eye(3) + 2 * (q * p)[:, :, None] * np.eye(3)
        return p + q * p**2, d_values, d_p

    def correct(self, acc_s, reported):
        q = np.array([*reported.value, 0.0])
        out = acc_s.copy()
        k = q != 0
        out[:, k] = (np.sqrt(1 + 4 * q[k] * acc_s[:, k]) - 1) / (2 * q[k])
        return out

    def spec_limits(self, spec):
        return {"quad_x": 0.002, "quad_y": 0.002}  # the datasheet's nonlinearity, as this package reads it

    def label(self, parameter):
        return "horizontal nonlinearity"
'''
Q_TRUE = np.array([0.05, -0.04])  # 1/(m/s²): 2β harmonics of ~7 mg on a 10° slope


def quadratic(acc_s: FloatArray, q: FloatArray = Q_TRUE) -> FloatArray:
    """What a sensor with the nonlinearity ``q`` (x, y) reads for the true ``acc_s``: the effect's model."""
    return acc_s + np.array([*q, 0.0]) * acc_s**2


@dataclass(frozen=True)
class Installed:
    path_entry: str  # the folder to put on sys.path (in process)
    env: dict[str, str]  # the environment of a subprocess that sees it (and this checkout's mountcal)


def install(folder: Path) -> Installed:
    """The plugin's module and its distribution's metadata written into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{MODULE}.py").write_text(SOURCE, encoding="utf-8")
    info = folder / f"{MODULE}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mc-quadratic\nVersion: 0.1\n", encoding="utf-8")
    entry = f"[{registry.GROUP}]\nquadratic = {MODULE}:Quadratic\n"
    (info / "entry_points.txt").write_text(entry, encoding="utf-8")
    return Installed(str(folder), {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(SRC)])})
