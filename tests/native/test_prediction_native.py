"""camdirector._native.KernelBank (native/src/prediction.rs), the compiled twin of
pipeline/toric/occlusion_prediction.py's KernelBank and predict_occlusion: over random S-maps and
V-maps (whole and partial occlusion, rigid-looking and scattered travels, still and clamped ones,
settings drawn), A_s agrees with the Python's to float32 rounding (the sums' order and libm's last
bits differ; a travel within rounding of a bin's edge could snap to the neighbour, which random
maps never hit); the same bits every time, and the bits of the entry-by-entry sums it was first
written with (a digest of its answers, kept when the kernels became runs of columns); bad shapes
refused."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from hypothesis import given

from camdirector import _native as native
from camdirector.geometry.toric_maps import MapWindow
from camdirector.pipeline.toric.anticipation_settings import AnticipationSettings
from camdirector.pipeline.toric.occlusion_prediction import KernelBank, predict_occlusion
from tests.pipeline.toric.test_occlusion_prediction import FAST, map_cases

A_S_TOL = 1e-6  # float32's rounding of A_s in [0, 1]


@FAST
@given(map_cases())
def test_the_compiled_prediction_equals_the_python_one(case):
    shadow, velocity, window, settings = case
    bank = native.KernelBank(settings)
    assert bank.max_radius == KernelBank(settings).max_radius
    compiled = bank.predict(shadow, velocity, window)
    assert compiled.shape == shadow.shape and compiled.dtype == np.float32
    np.testing.assert_allclose(compiled, predict_occlusion(shadow, velocity, window, settings), atol=A_S_TOL, rtol=0)
    assert bank.predict(shadow, velocity, window).tobytes() == compiled.tobytes()


# sha256 of the A_s below, from the prediction that added each kernel entry on its own (060516d's
# prediction.rs); a sum's order is a texel's, so adding a kernel's row as a run keeps every bit.
ENTRY_BY_ENTRY_SHA256 = "08fdd4f6c56526171ef955eeedc63cb5b05a094a35e1953a6f04c7bf36857d6e"


def test_the_prediction_keeps_the_bits_of_its_entry_by_entry_sums():
    bank = native.KernelBank(AnticipationSettings())
    window = MapWindow(theta_min_rad=0.2, phi_min_rad=-0.5, theta_step_rad=0.01, phi_step_rad=0.012, resolution=64)
    rng = np.random.default_rng(3)
    answers = []
    for scale in (0.05, 0.5, 2.0):  # still to clamped travels, kernels reaching past the window's edges
        shadow = (rng.random((10, 64, 64)) < 0.35).astype(np.float32)
        velocity = (rng.normal(size=(10, 64, 64, 2)) * scale).astype(np.float32)
        answers.append(bank.predict(shadow, velocity, window))
    assert hashlib.sha256(np.stack(answers).tobytes()).hexdigest() == ENTRY_BY_ENTRY_SHA256


def test_the_default_bank_on_full_windows_and_without_anticipation():
    rng = np.random.default_rng(3)
    window = MapWindow(1.0, 0.5, 0.02, 0.03, 64)
    for settings in (AnticipationSettings(), AnticipationSettings(anticipate=False)):
        bank = native.KernelBank(settings)
        for occluded_share in (0.02, 0.3, 1.0):
            shadow = (rng.random((2, 64, 64)) < occluded_share).astype(np.float32) * rng.random((2, 64, 64)).astype(np.float32)
            travel = rng.normal(size=2) * 8.0 + rng.normal(size=(2, 64, 64, 2))  # some clamped at 16 texels
            velocity = (travel * np.array([0.02, 0.03]) / settings.horizon_s).astype(np.float32)
            want = predict_occlusion(shadow, velocity, window, settings)
            np.testing.assert_allclose(bank.predict(shadow, velocity, window), want, atol=A_S_TOL, rtol=0)


def test_bad_shapes_are_refused():
    bank = native.KernelBank(AnticipationSettings())
    window = MapWindow(1.0, 0.5, 0.02, 0.03, 8)
    shadow, velocity = np.zeros((2, 8, 8), np.float32), np.zeros((2, 8, 8, 2), np.float32)
    with pytest.raises(ValueError, match="velocity_rad_s"):
        bank.predict(shadow, velocity[:1], window)
    with pytest.raises(ValueError, match="window of 16"):
        bank.predict(shadow, velocity, MapWindow(1.0, 0.5, 0.02, 0.03, 16))
    with pytest.raises(TypeError):
        bank.predict(shadow.astype(np.float64), velocity, window)
