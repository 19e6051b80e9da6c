"""The face of a numbered plate on a column (PartKind.SIGN, glsynth.world.others): dark digits
on a light enamel ground inside a dark border, drawn from a 3 x 5 cell font held here, so the
same number gives the same bytes on every machine (no font file, no font renderer)."""

import numpy as np

PLATE_PX = 128
"""The image's side; the plate is square and its face shows the whole image once."""

_DIGITS = ("111101101101111", "010110010010111", "111001111100111", "111001111001111",
           "101101111001001", "111100111001111", "111100111101111", "111001001001001",
           "111101111101111", "111101111001111")
"""Digits 0-9 as 5 rows of 3 cells, row by row from the top."""
_CELL_PX = 8
_GAP_PX = 8
_BORDER_PX = 6
_GROUND = (228, 228, 222)
_INK = (24, 32, 60)


def plate_image(number: int) -> np.ndarray:
    """(PLATE_PX, PLATE_PX, 3) uint8 sRGB: ``number`` (0-999) centred on the plate."""
    if not 0 <= number <= 999:
        raise ValueError(f"number = {number!r}: a plate shows 0 to 999")
    image = np.empty((PLATE_PX, PLATE_PX, 3), np.uint8)
    image[:] = _INK
    b = _BORDER_PX
    image[b:-b, b:-b] = _GROUND
    text = str(number)
    width = len(text) * 3 * _CELL_PX + (len(text) - 1) * _GAP_PX
    left, top = (PLATE_PX - width) // 2, (PLATE_PX - 5 * _CELL_PX) // 2
    for k, char in enumerate(text):
        cells = np.array([c == "1" for c in _DIGITS[int(char)]]).reshape(5, 3)
        glyph = np.kron(cells, np.ones((_CELL_PX, _CELL_PX), bool))
        x = left + k * (3 * _CELL_PX + _GAP_PX)
        image[top:top + glyph.shape[0], x:x + glyph.shape[1]][glyph] = _INK
    return image
