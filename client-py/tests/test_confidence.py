"""`dear.expected_error_m` decodes the expected-error confidence code as the Rust side defines it
(`dear_proto::confidence`: 1 mm · 2^((255 − v)/16), 0 = no depth)."""

from __future__ import annotations

import dear
import numpy as np


def test_codes_decode_to_the_documented_errors() -> None:
    codes = np.array([[255, 239, 202], [149, 96, 0]], dtype=np.uint8)
    err = dear.expected_error_m(codes)
    assert err.dtype == np.float32 and err.shape == codes.shape
    np.testing.assert_allclose(err[0], [0.001, 0.002, 0.01], rtol=0.03)
    np.testing.assert_allclose(err[1, :2], [0.1, 1.0], rtol=0.03)
    assert np.isnan(err[1, 2])
    # Monotone: a higher code is a smaller expected error.
    all_codes = dear.expected_error_m(np.arange(1, 256, dtype=np.uint8))
    assert np.all(np.diff(all_codes) < 0)
    assert abs(dear.ERROR_CODE_UNIT_M - 1e-3) < 1e-9
    assert dear.FLAG_CONFIDENCE_EXPECTED_ERROR == 1 << 6
