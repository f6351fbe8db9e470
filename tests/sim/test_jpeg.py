"""The camera's JPEG compression against the baseline JPEG's quantisation, computed here."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.fft import dctn

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import OpticsRealism
from cdpr_twin.sim import imaging

# ITU-T T.81 Annex K, Table K.1: the luminance quantisation table at quality 50
LUMA = np.array(
    [
        [16, 11, 10, 16, 24, 40, 51, 61],
        [12, 12, 14, 19, 26, 58, 60, 55],
        [14, 13, 16, 24, 40, 57, 69, 56],
        [14, 17, 22, 29, 51, 87, 80, 62],
        [18, 22, 37, 56, 68, 109, 103, 77],
        [24, 35, 55, 64, 81, 104, 113, 92],
        [49, 64, 78, 87, 103, 121, 120, 101],
        [72, 92, 95, 98, 112, 100, 103, 99],
    ]
)


def ijg_table(quality: int) -> np.ndarray:
    """The IJG (libjpeg ``jpeg_quality_scaling``) luminance table at a quality. (8, 8)."""
    scale = 5000 // quality if quality < 50 else 200 - 2 * quality
    return np.clip((LUMA * scale + 50) // 100, 1, 255)


def block_dct(img: np.ndarray) -> np.ndarray:
    """Each 8 × 8 block's DCT of the level-shifted frame (JPEG's, orthonormal). (B, 8, 8)."""
    h, w = img.shape
    blocks = (img.astype(float) - 128.0).reshape(h // 8, 8, w // 8, 8).swapaxes(1, 2)
    return dctn(blocks.reshape(-1, 8, 8), axes=(1, 2), norm="ortho")


@pytest.mark.parametrize("quality", [50, 85])
def test_jpeg_rounds_each_blocks_dct_to_the_quality_table(quality):
    rng = np.random.default_rng(0)
    # a smooth ramp with noise: coefficients fall anywhere between the table's multiples
    ramp = np.add.outer(np.linspace(60, 190, 64), np.linspace(0, 40, 96))
    frame = np.clip(ramp + rng.normal(0, 12, ramp.shape), 0, 255).astype(np.uint8)
    out = imaging.jpeg(frame, quality)
    q = ijg_table(quality)
    before, after = block_dct(frame), block_dct(out)
    # decoded coefficients sit on multiples of q, off by the decoder's rounding of each pixel to
    # an integer in 0…255 (|e| ≤ 0.5 per pixel: ≤ 4 in any orthonormal coefficient of 64) and the
    # integer DCT's own error (≤ 1)
    tol = 4.0 + 1.0
    off_grid = np.abs(after - q * np.round(after / q))
    coarse = q >= 2 * tol + 2  # where the grid is wider than the tolerance: a real test
    assert coarse.sum() > 20
    assert off_grid[:, coarse].max() <= tol
    # and the compression keeps each coefficient within half a step (plus the same tolerance)
    assert np.abs(after - before).max() <= (q / 2 + tol).max()
    assert np.all(np.abs(after - before) <= q / 2 + tol)
    # the uncompressed frame's coefficients are not on the grid: the check above could fail
    assert np.abs(before - q * np.round(before / q))[:, coarse].max() > 2 * tol


def test_jpeg_quality_is_refused_beyond_the_ijg_scale():
    with pytest.raises(OptionError, match="jpeg_quality"):
        OpticsRealism(jpeg_quality=101)
    assert OpticsRealism(jpeg_quality=85).forms
